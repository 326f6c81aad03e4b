//! Whole objects as a user meets them: `trispline fit torus.off --out DIR` with no flags,
//! `--domain`, `curvature` on the result, and the daemon fitting a torus dropped into its
//! folder (then a changed version of it, warm).

use crate::daemon_support::{config, read_json, setup};
use std::f64::consts::TAU;
use std::fmt::Write;
use std::path::Path;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
}

/// A torus (radii 1 and 0.35) on an `n x m` grid (`n`, `m` even) as OFF text; `wobble` moves every vertex
/// by up to that much (a rescan of the same object).
fn torus_off(n: usize, m: usize, wobble: f64) -> String {
    let mut s = format!("OFF\n{} {} 0\n", n * m, 2 * n * m);
    for i in 0..n {
        for j in 0..m {
            let (a, b) = (TAU * i as f64 / n as f64, TAU * j as f64 / m as f64);
            let h = wobble * (((i * m + j) * 7919 % 101) as f64 / 101.0 - 0.5);
            let r = 1.0 + (0.35 + h) * b.cos();
            let _ = writeln!(
                s,
                "{} {} {}",
                r * a.cos(),
                r * a.sin(),
                (0.35 + h) * b.sin()
            );
        }
    }
    let at = |i: usize, j: usize| (i % n) * m + j % m;
    for i in 0..n {
        for j in 0..m {
            let (p, q, r, t) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            // Alternating diagonals: valences 4 and 8, so no subdivision connectivity (a
            // one-way split would be a regular lattice, fitted on the exact path).
            if (i + j) % 2 == 0 {
                let _ = writeln!(s, "3 {p} {q} {r}\n3 {p} {r} {t}");
            } else {
                let _ = writeln!(s, "3 {p} {q} {t}\n3 {q} {r} {t}");
            }
        }
    }
    s
}

fn run(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().expect("runs");
    assert!(
        out.status.success(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn fit_with_no_flags_fits_a_whole_object() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("torus.off");
    std::fs::write(&input, torus_off(40, 16, 0.0)).expect("write");
    let fit = tmp.path().join("fit");
    let out = run(bin().arg("fit").arg(&input).arg("--out").arg(&fit));
    let report = read_json(&fit.join("report.json"));
    assert_eq!(report["path"], "object", "{report}");
    // A whole object that stops short of the tolerance is told the remedy that applies to
    // it (the control budget), not the scans' (noise and rims).
    let line = String::from_utf8_lossy(&out.stdout);
    assert!(!line.contains("usual for scans"), "{line}");
    assert_eq!(
        line.contains("--target-controls-pct"),
        report["status"] == "stalled",
        "{line}"
    );
    assert_eq!(report["surface"], "loop");
    assert_eq!(report["topology"]["control"]["genus"], 1);
    assert_eq!(report["topology"]["data"]["genus"], 1);
    // How far the surface strays from the data, against the bound (this coarse torus, 640
    // vertices and 16 facets round the tube, at 5 % controls: 0.66 %, over it).
    let stray = &report["object"]["stray"];
    let share = stray["share_of_diagonal"].as_f64().unwrap_or(f64::NAN);
    assert!(share > 0.0 && share < 0.05, "{stray}");
    assert_eq!(stray["limit_share"], 0.005);
    assert_eq!(stray["within"], share <= 0.005, "{stray}");
    let surface = read_json(&fit.join("surface.json"));
    assert_eq!(surface["layout"], "mesh");
    assert!(std::fs::metadata(fit.join("surface.glb")).map_or(0, |m| m.len()) > 1000);

    // `curvature` reads the control-mesh layout: a torus has a convex outside and a saddle
    // inside.
    let k = tmp.path().join("k");
    run(bin()
        .arg("curvature")
        .arg(fit.join("surface.json"))
        .args(["--grid", "41", "--out"])
        .arg(&k));
    let regions = read_json(&k.join("regions.json"));
    assert!(regions["convex"].as_u64().unwrap_or(0) >= 1, "{regions}");
    assert!(regions["saddle"].as_u64().unwrap_or(0) >= 1, "{regions}");

    // The planar map cannot take a torus: `--domain grid` refuses it, exit 2.
    let refused = bin()
        .arg("fit")
        .arg(&input)
        .args(["--domain", "grid", "--out"])
        .arg(tmp.path().join("grid"))
        .output()
        .expect("runs");
    assert_eq!(refused.status.code(), Some(2));
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("not disk-like"), "{err}");
}

#[test]
fn domain_mesh_fits_a_scan_patch_on_a_control_mesh() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("patch.ply");
    std::fs::write(&input, crate::daemon_support::patch_ply(20, 3)).expect("write");
    let fit = tmp.path().join("fit");
    run(bin()
        .arg("fit")
        .arg(&input)
        .args(["--domain", "mesh", "--out"])
        .arg(&fit));
    let report = read_json(&fit.join("report.json"));
    assert_eq!(report["path"], "object", "{report}");
    assert_eq!(report["topology"]["control"]["boundary_loops"], 1);
}

fn fitted_report(out: &Path, patch: &str) -> serde_json::Value {
    read_json(&out.join(patch).join("report.json"))
}

#[test]
fn daemon_fits_a_torus_dropped_into_its_folder_then_warm() {
    let s = setup(&config(0, "poll", "").replace("surface = \"bezier\"", "surface = \"loop\""));
    std::fs::write(s.inbox.join("ring.off"), torus_off(40, 16, 0.0)).expect("write");
    let first = s.once();
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let report = fitted_report(&s.out, "ring");
    assert_eq!(report["path"], "object", "{report}");
    assert_eq!(report["topology"]["control"]["genus"], 1);
    assert_eq!(report["object"]["warm"]["used"], false);
    assert_eq!(
        read_json(&s.out.join("ring").join("surface.json"))["layout"],
        "mesh"
    );

    // A rescan of the same ring: it starts from the stored control mesh.
    std::fs::write(s.inbox.join("ring.off"), torus_off(40, 16, 4e-3)).expect("write");
    let second = s.once();
    assert!(
        second.status.success(),
        "{}",
        String::from_utf8_lossy(&second.stderr)
    );
    let report = fitted_report(&s.out, "ring");
    assert_eq!(report["object"]["warm"]["used"], true, "{report}");
}

/// bun_zipper_res4, a broken 453-vertex decimation with 19 holes: its holes already take
/// more controls than the budget, and the stray repair (at most a tenth more) does not
/// bring the surface nearer, 3.0 % of the diagonal off the data (measured). The report and
/// the summary line say so. decimated-max at the default 5 % strayed 0.59 % before the
/// repair (0.47 % after, 279 controls for 264); repaired, it is within the bound, its
/// refinement says the repair ran, and the line says nothing.
/// bun_zipper_res4 holds faces repeated with the reverse orientation (zero-thickness
/// sheets) and non-manifold edges: the report says what cleaning did about them.
#[test]
fn the_report_says_what_cleaning_changed() {
    let Some(broken) = trispline::testdata::shared_data("models/bun_zipper_res4.ply") else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tmp");
    run(bin().arg("fit").arg(&broken).arg("--out").arg(tmp.path()));
    let cleaning = read_json(&tmp.path().join("report.json"))["object"]["cleaning"].clone();
    let count = |k: &str| cleaning[k].as_u64().unwrap_or(0);
    assert!(count("sheet_faces_removed") > 0, "{cleaning}");
    assert_eq!(
        count("sheet_faces_removed") % 2,
        0,
        "sheets go both sides: {cleaning}"
    );
    assert!(count("non_manifold_edges_split") > 0, "{cleaning}");
    assert!(count("pinch_vertices_split") > 0, "{cleaning}");
}

#[test]
fn fit_says_when_the_surface_strays_from_the_data() {
    let (Some(broken), Some(coarse_input)) = (
        trispline::testdata::shared_data("models/bun_zipper_res4.ply"),
        trispline::testdata::shared_data("models/decimated-max.obj"),
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tmp");
    let over = tmp.path().join("over");
    // Without the faceted last resort, which holds the bound on this broken mesh
    // (`fit_grows_the_budget_where_it_cannot_hold_the_shape`).
    let out = run(bin()
        .arg("fit")
        .arg(&broken)
        .args(["--faceted", "false"])
        .arg("--out")
        .arg(&over));
    let line = String::from_utf8_lossy(&out.stdout);
    let stray = read_json(&over.join("report.json"))["object"]["stray"].clone();
    assert_eq!(stray["within"], false, "{stray}");
    let share = stray["share_of_diagonal"].as_f64().unwrap_or(0.0);
    assert!(share > 0.005, "{stray}");
    assert!(line.contains("strays up to"), "{line}");
    assert!(line.contains(&format!("{:.2} %", 100.0 * share)), "{line}");

    let repaired = tmp.path().join("repaired");
    let out = run(bin()
        .arg("fit")
        .arg(&coarse_input)
        .arg("--out")
        .arg(&repaired));
    let line = String::from_utf8_lossy(&out.stdout);
    let report = read_json(&repaired.join("report.json"));
    let stray = report["object"]["stray"].clone();
    assert_eq!(stray["within"], true, "{stray}");
    assert_eq!(stray["lattice_segments"], 6, "{stray}");
    let refinement = report["object"]["refinement"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    assert!(
        refinement.iter().any(|r| r["stray_repair"] == true),
        "{refinement:?}"
    );
    assert!(!line.contains("strays"), "{line}");
    let added = report["object"]["control_points"].as_u64().unwrap_or(0)
        - refinement
            .iter()
            .rev()
            .find(|r| r["stray_repair"] != true)
            .and_then(|r| r["controls"].as_u64())
            .unwrap_or(0);
    assert!(added > 0, "{refinement:?}");
    assert!(
        line.contains(&format!(
            "{added} control points added where the surface strayed"
        )),
        "{line}"
    );
}

/// fertility at 2 % controls webs across its handles (1.2 % of the diagonal off the data)
/// and a decimation of as many vertices strays as far: `trispline fit` fits it again at
/// twice the controls it spent, keeps that surface (within the bound) and says so; with
/// `--stray-budget-steps 0` the budget holds and the line says the surface strays. On
/// bun_zipper_res4 (2 %) no smooth step comes within the bound: the faceted last resort
/// does, at more controls, and the line says so; with `--faceted false` the line says
/// the least straying smooth fit is kept.
#[test]
fn fit_grows_the_budget_where_it_cannot_hold_the_shape() {
    let (Some(genus_four), Some(broken)) = (
        trispline::testdata::shared_data("models/fertility.off"),
        trispline::testdata::shared_data("models/bun_zipper_res4.ply"),
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tmp");
    let fit_with = |name: &str, input: &Path, steps: &str, faceted: &str| {
        let dir = tmp.path().join(name);
        let out = run(bin()
            .arg("fit")
            .arg(input)
            .args(["--target-controls-pct", "2", "--stray-budget-steps", steps])
            .args(["--faceted", faceted])
            .arg("--out")
            .arg(&dir));
        let line = String::from_utf8_lossy(&out.stdout).into_owned();
        (line, read_json(&dir.join("report.json")))
    };
    let fit_at = |name: &str, input: &Path, steps: &str| fit_with(name, input, steps, "true");

    let (line, report) = fit_at("grown", &genus_four, "2");
    let object = &report["object"];
    let budgets = object["stray_budgets"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    assert_eq!(budgets.len(), 2, "{budgets:?}");
    assert_eq!(object["stray"]["within"], true, "{}", object["stray"]);
    assert_eq!(
        report["control_points"], budgets[1]["controls"],
        "{budgets:?}"
    );
    assert_eq!(object["topology"]["control"]["genus"], 4);
    assert!(object["stages"]["stray_budget_ms"].as_f64().unwrap_or(0.0) > 0.0);
    let again = format!(
        "the fit at {} control points strayed from the data, so it was fitted again at {} \
         (the surface of {} kept",
        budgets[0]["controls"], budgets[1]["target"], report["control_points"]
    );
    assert!(line.contains(&again), "{line}");

    let (line, report) = fit_at("held", &genus_four, "0");
    assert_eq!(report["object"]["stray_budgets"], serde_json::json!([]));
    assert_eq!(report["object"]["stray"]["within"], false);
    assert!(!line.contains("fitted again"), "{line}");
    assert!(line.contains("strays up to"), "{line}");

    let (line, report) = fit_at("last resort", &broken, "2");
    let budgets = report["object"]["stray_budgets"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let (smooth, faceted): (Vec<_>, Vec<_>) = budgets.iter().partition(|b| b["faceted"] != true);
    assert_eq!(smooth.len(), 3, "{budgets:?}");
    assert!(!faceted.is_empty(), "{budgets:?}");
    assert_eq!(report["object"]["stray"]["within"], true);
    let kept = budgets.last().cloned().unwrap_or_default();
    assert_eq!(
        (&kept["kept"], &kept["faceted"]),
        (&serde_json::json!(true), &serde_json::json!(true))
    );
    assert_eq!(report["control_points"], kept["controls"]);
    assert!(
        kept["controls"].as_u64() > smooth[2]["controls"].as_u64(),
        "{budgets:?}"
    );
    assert_eq!(report["object"]["faceted"]["kept_faceted"], true);
    let grown = format!(
        "{} faceted (the surface of {} kept",
        kept["target"], report["control_points"]
    );
    assert!(line.contains(&grown), "{line}");
    assert!(
        line.contains("faceted: every control edge is a crease"),
        "{line}"
    );
    // Named when the last resort went all the way to the data's own vertices.
    assert_eq!(
        line.contains("the surface is the cleaned input mesh itself"),
        report["control_points"] == report["data_points"],
        "{line}"
    );

    let (line, report) = fit_with("kept", &broken, "2", "false");
    let budgets = report["object"]["stray_budgets"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    assert_eq!(budgets.len(), 3, "{budgets:?}");
    assert_eq!(report["object"]["stray"]["within"], false);
    assert_eq!(budgets[2]["kept"], true, "{budgets:?}");
    assert_eq!(report["control_points"], budgets[2]["controls"]);
    let least = format!(
        "none came within the bound; the surface of {}, which strays least, is kept",
        report["control_points"]
    );
    assert!(line.contains(&least), "{line}");
}

/// A finely faceted part (a 32-sided prism, whose sides turn by too little for a crease):
/// the faceted surface is kept and the line says so; `--faceted false` keeps the smooth one.
#[test]
fn fit_keeps_the_facets_of_a_faceted_part_unless_told_not_to() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("prism.ply");
    let (prism, _) = trispline::testdata::faceted_prism(32, 6, 2);
    trispline::io::write_mesh_file(&input, &prism).expect("write");
    let fit_with = |name: &str, faceted: &str| {
        let dir = tmp.path().join(name);
        let out = run(bin()
            .arg("fit")
            .arg(&input)
            .args(["--target-controls-pct", "25", "--faceted", faceted])
            .arg("--out")
            .arg(&dir));
        let line = String::from_utf8_lossy(&out.stdout).into_owned();
        (
            line,
            read_json(&dir.join("report.json")),
            read_json(&dir.join("surface.json")),
        )
    };
    let (line, report, surface) = fit_with("faceted", "true");
    let choice = &report["object"]["faceted"];
    assert_eq!(choice["kept_faceted"], true, "{choice}");
    assert!(
        line.contains("faceted: every control edge is a crease"),
        "{line}"
    );
    let number = |v: &serde_json::Value| v.as_f64().expect("a number");
    assert!(number(&choice["faceted_rms"]) < 1e-3 * number(&choice["smooth_rms"]));
    assert_eq!(report["final"]["rms_error"], choice["faceted_rms"]);
    // Every interior control edge is written as a crease.
    let faces: Vec<[u32; 3]> =
        serde_json::from_value(surface["control_faces"].clone()).expect("control faces");
    let creases: Vec<[u32; 2]> =
        serde_json::from_value(surface["crease_edges"].clone()).expect("crease edges");
    assert!(trispline::pipeline::object::is_faceted(&faces, &creases));

    let (line, report, _) = fit_with("smooth", "false");
    assert_eq!(report["object"]["faceted"], serde_json::Value::Null);
    assert!(!line.contains("faceted"), "{line}");
}
