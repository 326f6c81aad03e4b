//! Incremental reconstruction of the bunny from its registered range scans.
//!
//!     cargo run --release --example object_session [-- DATA_DIR]
//!
//! 1. Registration check: each scan of `range_scans/registered/` moved by `bun.conf`
//!    (p' = R^T p + t, and for comparison p' = R p + t), median and p95 distance of its
//!    points to Stanford's `models/bun_zipper.ply`.
//! 2. The scans dropped one by one into an object session: per update the time (and its
//!    stages), the path, controls, merged points, the fit's RMS to the merged data and the
//!    changed region.
//! 3. At the end: each scan's distance to the surface beside its distance to bun_zipper;
//!    how much of bun_zipper lies within 0.5 mm of the surface where the scans cover it
//!    (a scan point within 1 mm), and of that, inside the scans' rim (scan points all
//!    around it); the misses inside the rim split by whether some scan's own triangles
//!    pass within 0.5 mm of them (else no view of the five has data there) and whether
//!    the merged data does (else the merge, not the fit, left them); and the same share
//!    over the vertices some scan's own triangles pass within 0.5 mm of (the strictest
//!    reading of coverage: a view measured the surface there).
//! 4. A new version of bun045 (its registration corrected by 30 um): the local update
//!    (merge around the scan, refit of the controls around it) beside the same update
//!    from scratch (`SessionOptions::cold`), their times and RMS and the two surfaces'
//!    distance.
//! 5. Folder changes as one update of the kept session: nothing changed (a rejected scan
//!    came), and bun000 renamed.
//! 6. The same scans in the reverse order: the two end surfaces' distance.
//!
//! After each update, how many of the surface's tessellation vertices lie over 0.5 mm from
//! the merged data (a bulge or a bad seam shows there).
//!
//! Times are wall and process CPU (user + sys, all threads) per update; every local merge
//! is checked against a merge from scratch of the same scans.
//!
//! Beside 3, bun_zipper's vertices are split by whether the merged data already misses
//! them (the merge's fault) or only the surface does (the fit's). `OBJ_SESSION_MERGE_ONLY=1`
//! times the merges alone (scan by scan and from scratch, best of three, with fingerprints
//! of their bits) and compares the merge of all scans with bun_zipper (no fit),
//! `OBJ_SESSION_FORWARD_ONLY=1`
//! only the updates in arrival order, `OBJ_SESSION_REPLACE_ONLY=1` those and the new
//! version of bun045, `OBJ_SESSION_REVERSE_ONLY=1` only the updates in reverse order; `OBJ_SESSION_DUMP=FILE`
//! writes the bun_zipper vertices over 0.5 mm from both the merged data and the surface
//! (x y z, then those two distances), `FILE.inside` the misses inside the scans' rim
//! the same way, and `FILE.strict` the misses on a scan's own surface (x y z, then the
//! distances to the surface and to the nearest scan's triangles);
//! `OBJ_SESSION_DUMP_SCAN=ID` one scan's points with their
//! distances and rim ring to /tmp/scan_dump.txt. Variants: `OBJ_MERGE_KEEP_CELLS`,
//! `OBJ_MERGE_CELL_EDGES`, `OBJ_MERGE_RIM_WEIGHT`, `OBJ_MERGE_OVERHANG`,
//! `OBJ_MERGE_RADIUS_CELLS` (the `[object.merge]` options), `OBJ_SESSION_PCT` (controls), `OBJ_SESSION_ROUNDS` (correction rounds); `OBJ_SESSION_MEASURE=1` measures every scan against the
//! surface in each update, as the daemon does; `OBJ_SESSION_SAVE_SURFACE=FILE` writes the
//! final surface's tessellation (arrival order); `OBJ_SESSION_SAVE_MERGED=DIR` writes each
//! update's merged mesh (from scratch) to `DIR/merged_<vertices>.ply`, so that its fit can
//! be studied alone (`object_table` with `OBJ_FILES`).

use std::path::{Path, PathBuf};
use trispline::io::registration::registration_for;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::rigid::RigidTransform;
use trispline::pipeline::merge::{merge, MergeField, ScanSamples};
use trispline::pipeline::object_session::{
    distance_stats, surface_mesh, surface_points_at_data, DistanceStats, ObjectSession,
    SessionOptions, SessionUpdate,
};
use trispline::pipeline::scattered::process_cpu_ms;
use trispline::{DVec3, TriMesh};

mod session_coverage;

// The daemon's allocator, so that the update times are the daemon's.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

const SCANS: [&str; 5] = ["bun000", "bun045", "bun180", "bun270", "chin"];

fn um(x: f64) -> f64 {
    x * 1e6
}

fn row(stats: &DistanceStats) -> String {
    format!(
        "median {:6.1} um  p95 {:6.1} um  rms {:6.1} um",
        um(stats.median),
        um(stats.p95),
        um(stats.rms)
    )
}

fn main() {
    trispline::allocator::keep_freed_memory();
    trispline::allocator::small_pages_only();
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let folder = root.join("range_scans/registered");
    let load = |p: &Path| -> TriMesh {
        match read_mesh_file(p, &LoadOptions::default()) {
            Ok(l) => l.mesh,
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
    };
    let zipper = load(&root.join("models/bun_zipper.ply"));
    let mut scans = Vec::new();
    println!("== registration: scan points to bun_zipper (VRIP, ten views)");
    for id in SCANS {
        let path = folder.join(format!("{id}.ply"));
        let mesh = load(&path);
        let registration = match registration_for(&path, id) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        };
        let moved = |t: &RigidTransform| -> Vec<DVec3> {
            let used = used_vertices(&mesh);
            used.iter().map(|&v| t.apply(mesh.positions[v])).collect()
        };
        let rt = distance_stats(&moved(&registration.transform), &zipper);
        // Points centimetres off make the distance query search far: every 50th is enough.
        let wrong: Vec<DVec3> = moved(&registration.transform.with_rotation_transposed())
            .into_iter()
            .step_by(50)
            .collect();
        let r = distance_stats(&wrong, &zipper);
        println!(
            "{id:7} R^T p + t: {}   | R p + t: median {:8.1} um",
            row(&rt),
            um(r.median)
        );
        scans.push((id, mesh, registration.transform, rt));
    }

    let mut opts = SessionOptions {
        measure_scans: false,
        ..Default::default()
    };
    // Variants for comparison runs, from the environment.
    let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<f64>().ok());
    if let Some(k) = env("OBJ_MERGE_KEEP_CELLS") {
        opts.merge.keep_cells = k;
    }
    if let Some(c) = env("OBJ_MERGE_CELL_EDGES") {
        opts.merge.cell_edges = c;
    }
    if let Some(w) = env("OBJ_MERGE_RIM_WEIGHT") {
        opts.merge.rim_weight = w;
    }
    if let Some(p) = env("OBJ_SESSION_PCT") {
        opts.worker.fit.scan.target_controls_pct = p;
    }
    if let Some(r) = env("OBJ_SESSION_ROUNDS") {
        opts.worker.fit.correction.rounds = r as usize;
    }
    if std::env::var("OBJ_SESSION_MEASURE").is_ok() {
        opts.measure_scans = true;
    }
    if let Some(o) = env("OBJ_MERGE_OVERHANG") {
        opts.merge.rim_overhang_cells = o;
    }
    if let Some(r) = env("OBJ_MERGE_RADIUS_CELLS") {
        opts.merge.radius_cells = r;
    }
    if std::env::var("OBJ_SESSION_MERGE_ONLY").is_ok() {
        merge_only(&scans, &opts, &zipper);
        return;
    }
    if std::env::var("OBJ_SESSION_REVERSE_ONLY").is_ok() {
        let reversed: Vec<_> = scans.iter().rev().cloned().collect();
        run(&reversed, opts, "reverse order");
        return;
    }
    let (forward, mut session) = run(&scans, opts.clone(), "arrival order");
    // Only the updates in arrival order (a quicker look at their figures).
    if std::env::var("OBJ_SESSION_FORWARD_ONLY").is_ok() {
        return;
    }
    replacement(&scans, &mut session, &opts);
    folder_changes(&scans, &mut session);
    if std::env::var("OBJ_SESSION_REPLACE_ONLY").is_ok() {
        return;
    }
    println!("\n== each scan's points: to the surface vs to bun_zipper");
    let surface = surface_mesh(&forward);
    let mut ratios = Vec::new();
    for (id, mesh, t, zipper_stats) in &scans {
        let points: Vec<DVec3> = used_vertices(mesh)
            .iter()
            .map(|&v| t.apply(mesh.positions[v]))
            .collect();
        let ours = distance_stats(&points, &surface);
        println!("{id:7} surface:    {}", row(&ours));
        println!("{:7} bun_zipper: {}", "", row(zipper_stats));
        ratios.push((
            ours.median / zipper_stats.median,
            ours.p95 / zipper_stats.p95,
        ));
    }
    for ((id, ..), (m, p)) in scans.iter().zip(&ratios) {
        println!("{id:7} ratio to VRIP: median {m:.2}x  p95 {p:.2}x");
    }
    if let Ok(file) = std::env::var("OBJ_SESSION_SAVE_SURFACE") {
        if let Err(e) = trispline::io::write_mesh_file(Path::new(&file), &surface) {
            eprintln!("could not write {file}: {e}");
        }
    }
    let missed_inside = session_coverage::coverage_check(&scans, &surface, &zipper);
    session_coverage::merged_coverage(&session, &opts, &surface, &zipper, &missed_inside);

    let reversed: Vec<_> = scans.iter().rev().cloned().collect();
    let (backward, _) = run(&reversed, opts, "reverse order");
    let other = surface_mesh(&backward);
    let ab = distance_stats(&surface_points_at_data(&forward), &other);
    let ba = distance_stats(&surface_points_at_data(&backward), &surface);
    println!(
        "\n== order independence: forward surface to reverse surface rms {:.1} um (p95 {:.1}), reverse to forward rms {:.1} um (p95 {:.1})",
        um(ab.rms),
        um(ab.p95),
        um(ba.rms),
        um(ba.p95)
    );
}

type Scan<'a> = (&'a str, TriMesh, RigidTransform, DistanceStats);

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|l| l.split_whitespace().next().unwrap_or("?").to_string())
        .unwrap_or_else(|_| "?".into())
}

/// The whole fit's refinement rounds, `controls:rms(beyond)` each (`-` for none): each
/// is a whole refit, so they are where an update's fit time goes.
fn refinement_line(rounds: &serde_json::Value) -> String {
    let Some(rounds) = rounds.as_array().filter(|r| !r.is_empty()) else {
        return "-".into();
    };
    rounds
        .iter()
        .map(|r| {
            let repair = if r["stray_repair"] == true {
                " repair"
            } else {
                ""
            };
            format!(
                "{}:{:.1}({}){repair}",
                r["controls"],
                r["rms"].as_f64().unwrap_or(f64::NAN) * 1e6,
                r["beyond"]
            )
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// One update's line: times (wall and CPU), path, how it was fitted, the merged region.
fn describe(id: &str, u: &SessionUpdate, cpu_ms: f64) -> String {
    let session = &u.outputs.report["session"];
    let fitted = match (&u.local, &u.cold_because) {
        (Some(l), _) => format!(
            "local: {} controls refitted, {} changed / {} moving points, {} rounds",
            l.controls.len(),
            l.changed_points,
            l.moving_points,
            l.rounds
        ),
        (None, Some(why)) => format!("whole fit ({why})"),
        (None, None) => "whole fit".into(),
    };
    // The worker's own account: whether it started from the previous fit (or why not),
    // and whether it extended it over new ground.
    let object = &u.outputs.report["object"];
    let stage = |k: &str| object["stages"][k].as_f64().unwrap_or(0.0);
    let fitted = format!(
        "{fitted}\n        refinement (controls:rms um, beyond the tolerance) {}\n        worker: warm {}  new ground points {}  stages ms: clean {:.0} simplify {:.0} first {:.0} rounds {:.0} refine {:.0}",
        refinement_line(&object["refinement"]),
        object["warm"],
        object["local"]["new_ground_points"],
        stage("clean_ms"),
        stage("simplify_ms"),
        stage("first_fit_ms"),
        stage("rounds_ms"),
        stage("refine_ms"),
    );
    format!(
        "{id:7} {:7.0} ms wall {:7.0} ms cpu (merge {:5.0}, fit {:6.0}, outputs {:5.0}, measure {:4.0}) load {}  path {:6}  views {:3.0} deg  controls {:5}  merged {:6} ({} cells recomputed)  rms {:5.1} um  changed +{} -{} ~{} ={}\n        {fitted}",
        u.times.total_ms,
        cpu_ms,
        u.times.merge_ms,
        u.times.fit_ms,
        u.times.outputs_ms,
        u.times.measure_ms,
        load_average(),
        u.path,
        session["view_spread_deg"].as_f64().unwrap_or(f64::NAN),
        u.fit.controls.len(),
        u.merged_vertices,
        u.recomputed_cells,
        um(u.fit.geometric_rms()),
        u.change.added,
        u.change.removed,
        u.change.moved,
        u.change.kept,
    )
}

fn run(
    scans: &[Scan],
    opts: SessionOptions,
    label: &str,
) -> (trispline::pipeline::PatchFit, ObjectSession) {
    println!("\n== session, {label}");
    let mut session = ObjectSession::new(opts.clone());
    let mut last = None;
    for (id, mesh, t, _) in scans {
        let cpu = process_cpu_ms();
        match session.add_scan(id, mesh, *t) {
            Ok(u) => {
                println!("+{}", describe(id, &u, process_cpu_ms() - cpu));
                check_merge(&session, &opts, &u);
                last = Some(u.fit);
            }
            Err(e) => {
                eprintln!("{id}: {e} ({})", e.kind());
                std::process::exit(1);
            }
        }
    }
    if let Some(cell) = session.cell() {
        println!("merge cell {:.3} mm", cell * 1e3);
    }
    match last {
        Some(f) => (f, session),
        None => std::process::exit(1),
    }
}

/// The session's merge against a merge from scratch of the same scans, with its time.
fn check_merge(session: &ObjectSession, opts: &SessionOptions, update: &SessionUpdate) {
    let vertices = update.merged_vertices;
    let Some(cell) = session.cell() else {
        return;
    };
    let all: Vec<_> = session.scans().values().map(|s| &s.samples).collect();
    let (t, cpu) = (std::time::Instant::now(), process_cpu_ms());
    let cold = merge(&all, cell, &opts.merge);
    if let Ok(dir) = std::env::var("OBJ_SESSION_SAVE_MERGED") {
        let file = Path::new(&dir).join(format!("merged_{vertices}.ply"));
        if let Err(e) = trispline::io::write_mesh_file(&file, &cold.mesh) {
            eprintln!("{}: {e}", file.display());
        }
    }
    println!(
        "        merge from scratch: {:.0} ms wall {:.0} ms cpu, {} vertices ({})",
        t.elapsed().as_secs_f64() * 1e3,
        process_cpu_ms() - cpu,
        cold.mesh.positions.len(),
        if cold.mesh.positions.len() == vertices {
            "same count as the local merge"
        } else {
            "DIFFERS from the local merge"
        }
    );
    // A surface that strays from the data (a bulge over a hole, a badly joined seam)
    // shows here, where no distance from the data to the surface would.
    let to_merged = MeshDistance::new(&cold.mesh);
    let surface = surface_mesh(&update.fit);
    let far = distances_beyond(&surface.positions, &to_merged, 5e-4);
    println!(
        "        surface vertices over 0.5 mm from the merged data: {} of {} (farthest {:.2} mm)",
        far.len(),
        surface.positions.len(),
        far.iter().fold(0.0f64, |a, &b| a.max(b)) * 1e3
    );
}

/// The distances from `points` to the mesh of `to` that exceed `limit`.
fn distances_beyond(points: &[DVec3], to: &MeshDistance, limit: f64) -> Vec<f64> {
    points
        .iter()
        .filter_map(|p| to.distance(*p))
        .filter(|&d| d > limit)
        .collect()
}

/// A new version of bun045, its registration moved by 30 um: locally and from scratch.
fn replacement(scans: &[Scan], session: &mut ObjectSession, opts: &SessionOptions) {
    let Some((id, mesh, t, _)) = scans.iter().find(|s| s.0 == "bun045") else {
        return;
    };
    let corrected = RigidTransform {
        translation: t.translation + DVec3::new(30e-6, 0.0, 0.0),
        ..*t
    };
    println!("\n== a new version of {id}: registration moved 30 um along x");
    let mut cold = ObjectSession::new(SessionOptions {
        cold: true,
        ..opts.clone()
    });
    let staged: Vec<(&str, &TriMesh, RigidTransform)> =
        scans.iter().map(|s| (s.0, &s.1, s.2)).collect();
    if let Err(e) = cold.add_scans(&staged) {
        eprintln!("{e}");
        return;
    }
    let mut fits = Vec::new();
    for (label, s) in [("local", &mut *session), ("cold", &mut cold)] {
        let cpu = process_cpu_ms();
        match s.add_scan(id, mesh, corrected) {
            Ok(u) => {
                println!("{label:5} {}", describe(id, &u, process_cpu_ms() - cpu));
                check_merge(s, opts, &u);
                fits.push(u.fit);
            }
            Err(e) => eprintln!("{label}: {e}"),
        }
    }
    if let [local, cold] = &fits[..] {
        let d = distance_stats(&surface_points_at_data(local), &surface_mesh(cold));
        println!(
            "local surface to the surface from scratch: rms {:.1} um, p95 {:.1} um, max {:.1} um",
            um(d.rms),
            um(d.p95),
            um(d.max)
        );
    }
}

/// Folder changes a daemon passes to its kept session as one update: nothing changed but
/// the outputs are wanted again (a rejected scan came or went), and a scan renamed.
fn folder_changes(scans: &[Scan], session: &mut ObjectSession) {
    let Some((id, mesh, t, _)) = scans.iter().find(|s| s.0 == "bun000") else {
        return;
    };
    println!("\n== folder changes, each one update of the kept session");
    let renamed = format!("{id}_renamed");
    let renamed_scan = [(renamed.as_str(), mesh, *t)];
    for (label, added, removed) in [
        ("unchanged", &renamed_scan[..0], &[][..]),
        ("renamed", &renamed_scan[..], &[*id][..]),
    ] {
        let cpu = process_cpu_ms();
        match session.change_scans(added, removed) {
            Ok(u) => println!("{label:9} {}", describe(id, &u, process_cpu_ms() - cpu)),
            Err(e) => eprintln!("{label}: {e}"),
        }
    }
}

/// The merges of a session in arrival order (each scan added to the kept field, as an
/// update does) and the merge of all scans from scratch, best of three each, with a
/// fingerprint of each result so that a faster merge can be checked to give the same bits.
fn merge_timings(
    all: &[(&str, &TriMesh, RigidTransform)],
    refs: &[&ScanSamples],
    cell: f64,
    opts: &SessionOptions,
) {
    const RUNS: usize = 3;
    let mut best = vec![f64::MAX; refs.len()];
    let mut prints = vec![0; refs.len()];
    for _ in 0..RUNS {
        let mut field = MergeField::new(cell);
        for k in 0..refs.len() {
            let t = std::time::Instant::now();
            let merged = field.update(&refs[..=k], &refs[k..=k], &[], &opts.merge);
            best[k] = best[k].min(t.elapsed().as_secs_f64() * 1e3);
            prints[k] = fingerprint(&merged.mesh);
        }
    }
    for (k, (id, _, _)) in all.iter().enumerate() {
        println!(
            "merge +{id:<8} best of {RUNS}: {:6.1} ms, fingerprint {:016x}",
            best[k], prints[k]
        );
    }
    let mut scratch = f64::MAX;
    for _ in 0..RUNS {
        let t = std::time::Instant::now();
        merge(refs, cell, &opts.merge);
        scratch = scratch.min(t.elapsed().as_secs_f64() * 1e3);
    }
    println!("merge of all scans from scratch, best of {RUNS}: {scratch:.1} ms");
}

/// A hash of a mesh's position bits and triangles.
fn fingerprint(mesh: &TriMesh) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    for p in &mesh.positions {
        p.to_array().map(f64::to_bits).hash(&mut hasher);
    }
    mesh.triangles.hash(&mut hasher);
    hasher.finish()
}

/// The merge of all scans alone against bun_zipper (no fit): its coverage and time.
fn merge_only(scans: &[Scan], opts: &SessionOptions, zipper: &TriMesh) {
    let all: Vec<_> = scans.iter().map(|(id, m, t, _)| (*id, m, *t)).collect();
    let samples: Vec<_> = all
        .iter()
        .map(|(_, m, t)| trispline::pipeline::merge::scan_samples(m, t, &opts.merge))
        .collect();
    let spacings = all
        .iter()
        .map(|(_, m, _)| trispline::pipeline::merge::median_edge(m));
    let Some(cell) = trispline::pipeline::object_session::object_cell(spacings, &opts.merge) else {
        return;
    };
    let refs: Vec<_> = samples.iter().collect();
    merge_timings(&all, &refs, cell, opts);
    let t = std::time::Instant::now();
    let merged = merge(&refs, cell, &opts.merge);
    println!(
        "merge of all scans: cell {:.3} mm, {} vertices, {:.0} ms, {} holes closed, {} boundary loops, fingerprint {:016x}",
        cell * 1e3,
        merged.mesh.positions.len(),
        t.elapsed().as_secs_f64() * 1e3,
        merged.closed_holes,
        trispline::mesh::stats::mesh_stats(&merged.mesh, 0).boundary_loops,
        fingerprint(&merged.mesh),
    );
    let merged = merged.mesh;
    let to_merged = MeshDistance::new(&merged);
    let mut dump = String::new();
    let (mut near, mut far) = (0, 0);
    for p in &zipper.positions {
        let Some(d) = to_merged.distance(*p) else {
            continue;
        };
        if d <= 2e-3 {
            near += 1;
            if d > 5e-4 {
                far += 1;
                dump += &format!("{} {} {} {d}\n", p.x, p.y, p.z);
            }
        }
    }
    println!("bun_zipper vertices within 2 mm of the merge: {near}, over 0.5 mm: {far}");
    let to_zipper = MeshDistance::new(zipper);
    let off: Vec<f64> = merged
        .positions
        .iter()
        .filter_map(|p| to_zipper.distance(*p))
        .collect();
    println!(
        "merged vertices from bun_zipper: over 0.5 mm {}, over 2 mm {}, max {:.2} mm",
        off.iter().filter(|&&d| d > 5e-4).count(),
        off.iter().filter(|&&d| d > 2e-3).count(),
        off.iter().fold(0.0f64, |m, &d| m.max(d)) * 1e3
    );
    for (id, mesh, t, zipper_stats) in scans {
        let points: Vec<DVec3> = used_vertices(mesh)
            .iter()
            .map(|&v| t.apply(mesh.positions[v]))
            .collect();
        let to_merge = distance_stats(&points, &merged);
        if std::env::var("OBJ_SESSION_DUMP_SCAN").is_ok_and(|s| s == *id) {
            dump_scan(mesh, t, &merged, zipper);
        }
        println!("{id:7} to the merge: {}", row(&to_merge));
        println!("{:7} bun_zipper:   {}", "", row(zipper_stats));
    }
    if let Ok(path) = std::env::var("OBJ_SESSION_DUMP") {
        let _ = std::fs::write(path, dump);
    }
}

/// Every used vertex of one scan: position, distance to the merge and to bun_zipper, and
/// its ring from the scan's rim (0 on it), to /tmp/scan_dump.txt.
fn dump_scan(mesh: &TriMesh, t: &RigidTransform, merged: &TriMesh, zipper: &TriMesh) {
    let mut edges: std::collections::HashMap<(u32, u32), u32> = Default::default();
    for tri in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let n = mesh.positions.len();
    let mut ring = vec![usize::MAX; n];
    let mut next = Vec::new();
    for (&(a, b), &c) in &edges {
        if c == 1 {
            for v in [a, b] {
                ring[v as usize] = 0;
                next.push(v);
            }
        }
    }
    let mut neighbours = vec![Vec::new(); n];
    for &(a, b) in edges.keys() {
        neighbours[a as usize].push(b);
        neighbours[b as usize].push(a);
    }
    let mut level = 0;
    while !next.is_empty() && level < 20 {
        level += 1;
        let mut grown = Vec::new();
        for v in next {
            for &w in &neighbours[v as usize] {
                if ring[w as usize] == usize::MAX {
                    ring[w as usize] = level;
                    grown.push(w);
                }
            }
        }
        next = grown;
    }
    let (qm, qz) = (MeshDistance::new(merged), MeshDistance::new(zipper));
    let mut out = String::new();
    for v in used_vertices(mesh) {
        let p = t.apply(mesh.positions[v]);
        let (Some(dm), Some(dz)) = (qm.distance(p), qz.distance(p)) else {
            continue;
        };
        out += &format!("{} {} {} {dm} {dz} {}\n", p.x, p.y, p.z, ring[v].min(99));
    }
    let _ = std::fs::write("/tmp/scan_dump.txt", out);
}

fn used_vertices(mesh: &TriMesh) -> Vec<usize> {
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        for &v in t {
            if let Some(u) = used.get_mut(v as usize) {
                *u = true;
            }
        }
    }
    (0..used.len()).filter(|&v| used[v]).collect()
}
