//! The faceted candidate of sharp-edged objects (`pipeline::object::faceted`): a Loop
//! surface with every control edge a crease is its control mesh, and it is kept where it
//! is nearer the data than the smooth surface.

use glam::DVec3;
use trispline::io::surface_json::{parse_surface_json, SurfaceDescription};
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::simplify::baseline::decimation_baselines;
use trispline::pipeline::object::{
    fit_object, fit_on_creased_control_mesh, is_faceted, ObjectFit, ObjectOptions,
};
use trispline::pipeline::worker::{run_patch, Domain, WorkerConfig};
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::testdata::{faceted_prism, torus};
use trispline::TriMesh;

/// A 32-sided prism: its sides turn by 11.25 degrees, too little for a crease, so the
/// smooth surface rounds them, while 66 vertices hold it exactly.
fn fine_prism() -> TriMesh {
    faceted_prism(32, 6, 2).0
}

fn rms_max(points: &[DVec3], mesh: &TriMesh) -> (f64, f64) {
    let near = MeshDistance::new(mesh);
    let d: Vec<f64> = points
        .iter()
        .map(|p| near.distance(*p).expect("a finite distance"))
        .collect();
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
    (rms, d.iter().copied().fold(0.0, f64::max))
}

fn control_mesh(fit: &ObjectFit) -> TriMesh {
    TriMesh::new(fit.controls.clone(), fit.surface.faces().to_vec())
}

/// The limit surface at scattered parameters of every face against the flat triangle of
/// its three controls: the largest gap.
fn gap_to_control_mesh(fit: &ObjectFit) -> f64 {
    let evaluate = fit.surface.evaluator(&fit.controls);
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut uniform = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut worst = 0.0f64;
    for (f, t) in fit.surface.faces().iter().enumerate() {
        for _ in 0..8 {
            let (a, b) = (uniform(), uniform());
            let (u, v) = if a + b > 1.0 {
                (1.0 - a, 1.0 - b)
            } else {
                (a, b)
            };
            let [p0, p1, p2] = t.map(|c| fit.controls[c as usize]);
            let flat = p0 * u + p1 * v + p2 * (1.0 - u - v);
            let on = evaluate(SurfaceParam {
                face: f as u32,
                u,
                v,
            })
            .position;
            worst = worst.max(on.distance(flat));
        }
    }
    worst
}

/// `mesh` fitted with `target` controls at the defaults, and the same without the faceted
/// candidate: the smooth fit the candidate was weighed against.
fn with_and_without_candidate(mesh: &TriMesh, target: usize) -> (ObjectFit, ObjectFit) {
    let opts = ObjectOptions {
        target_controls: Some(target),
        ..ObjectOptions::default()
    };
    let fit = fit_object(mesh, &opts).expect("fitted");
    let smooth = fit_object(
        mesh,
        &ObjectOptions {
            faceted_candidate: false,
            ..opts
        },
    )
    .expect("fitted");
    (fit, smooth)
}

#[test]
fn a_finely_faceted_part_is_fitted_by_its_facets() {
    let (fit, smooth) = with_and_without_candidate(&fine_prism(), 100);
    let diag = fit.component.bounds_diagonal();
    let choice = fit
        .faceted
        .expect("a part with sharp rims tries the candidate");
    let (rms, max) = rms_max(&fit.data, &control_mesh(&fit));
    let [_, plain] = decimation_baselines(&fit.component, fit.controls.len())
        .map(|qem| qem.expect("the decimation baseline").mesh);
    let (qem_rms, qem_max) = rms_max(&fit.data, &plain);
    let gap = gap_to_control_mesh(&fit);
    println!(
        "32-sided prism {} points, {} controls: faceted RMS {rms:.3e} max {max:.3e}, surface to \
         control mesh {gap:.1e}; smooth RMS {:.3e} max {:.3e}; plain QEM RMS {qem_rms:.3e} max \
         {qem_max:.3e}; candidate {:.0} ms",
        fit.data.len(),
        fit.controls.len(),
        smooth.rms,
        smooth.max,
        choice.ms
    );
    assert!(choice.kept_faceted, "{choice:?}");
    assert!(
        smooth.faceted.is_none(),
        "the candidate ran while switched off"
    );
    assert!(is_faceted(fit.surface.faces(), fit.surface.crease_edges()));
    assert_eq!(
        choice.smooth_rms, smooth.rms,
        "the same smooth fit was compared"
    );
    // Every vertex a corner and every edge a crease: the limit surface is the mesh.
    assert!(
        gap < 1e-12 * diag,
        "the surface is {gap} off its control mesh"
    );
    assert_eq!(fit.controls.len(), plain.positions.len());
    let floor = 1e-9 * diag;
    assert!(rms <= qem_rms.max(floor), "RMS {rms} vs QEM {qem_rms}");
    assert!(
        max <= 1.5 * qem_max.max(floor),
        "max {max} vs QEM {qem_max}"
    );
    assert!(
        smooth.rms > 100.0 * rms.max(floor),
        "the smooth surface ({}) is as near as the facets ({rms})",
        smooth.rms
    );
}

/// Smooth data that the smooth surface holds within the stray bound: no candidate.
#[test]
fn smooth_data_never_pays_for_the_faceted_candidate() {
    let opts = ObjectOptions {
        target_controls_pct: 20.0,
        ..ObjectOptions::default()
    };
    let fit = fit_object(&torus(24, 12), &opts).expect("fitted");
    let limit = 0.005 * fit.component.bounds_diagonal();
    assert!(
        fit.stray.is_some_and(|s| s <= limit),
        "the smooth fit strays {:?} (bound {limit})",
        fit.stray
    );
    assert!(fit.faceted.is_none(), "{:?}", fit.faceted);
    assert_eq!(fit.times.faceted_ms, 0.0);
    assert!(!is_faceted(fit.surface.faces(), fit.surface.crease_edges()));
}

/// The report says which surface was kept, and a new version of a faceted part is refitted
/// from the faceted control mesh (without the fairness term, which would draw its corners
/// together): it stays faceted and on the facets.
#[test]
fn a_new_version_of_a_faceted_part_stays_faceted() {
    let mesh = fine_prism();
    let mut cfg = WorkerConfig::default();
    cfg.fit.domain = Domain::Auto;
    cfg.fit.scan.target_controls_pct = 25.0;
    // A tolerance only the facets can meet: the rounds run on to their stall.
    cfg.fit.budget.tolerance_rel = 1e-8;
    let first = run_patch(&mesh, None, &cfg).expect("the prism fits");
    let faceted = &first.report["object"]["faceted"];
    assert_eq!(faceted["kept_faceted"], true, "{faceted}");
    assert!(first.report["object"]["stages"]["faceted_ms"].as_f64() > Some(0.0));
    let faceted_surface = |s: &serde_json::Value| {
        let bytes = serde_json::to_vec(s).expect("json");
        match parse_surface_json(&bytes, "prism").expect("reads back") {
            SurfaceDescription::LoopMesh { surface, .. } => {
                is_faceted(surface.faces(), surface.crease_edges())
            }
            _ => panic!("a whole object reads back as another kind"),
        }
    };
    assert!(faceted_surface(&first.surface));
    // Flat faces fitted exactly: the shown tessellation stays at the configured density,
    // not refined for the chord errors' rounding.
    let per_face = first.report["tessellation"]["per_face"]
        .as_f64()
        .expect("segments per face");
    let faces = first.surface["control_faces"]
        .as_array()
        .expect("control faces")
        .len() as f64;
    let start = (cfg.tessellation as f64 / faces.sqrt()).ceil().max(2.0);
    assert_eq!(per_face, start);
    // Stretched by 0.2 % along x: every point moves, the facets stay planes.
    let stretched = TriMesh::new(
        mesh.positions
            .iter()
            .map(|p| DVec3::new(1.002 * p.x, p.y, p.z))
            .collect(),
        mesh.triangles.clone(),
    );
    let second = run_patch(&stretched, Some(&first.warm), &cfg).expect("fits warm");
    assert_eq!(second.report["object"]["warm"]["used"], true);
    assert!(faceted_surface(&second.surface));
    let rms = second.report["final"]["rms_error"]
        .as_f64()
        .expect("an RMS");
    let diag = stretched.bounds_diagonal();
    // The foot points slide along the stretched facets a little each round: 4e-6 of the
    // diagonal at the stall; the smooth surface stands near 1e-3 of it off.
    assert!(rms < 1e-5 * diag, "the refit stands {rms} off the facets");
}

/// A coarse torus whose vertices are jolted off the smooth torus (a low-poly model of a
/// rough part, no edge sharp enough for a crease): even with over half its vertices as
/// controls the smooth surface cannot follow the jolts and bulges off the facets.
fn jolted_torus() -> TriMesh {
    let mut mesh = torus(32, 12);
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    for p in &mut mesh.positions {
        let centre = DVec3::new(p.x, p.y, 0.0).normalize();
        let off = *p - centre;
        *p = centre + off * (1.0 + 0.5 * (trispline::testdata::uniform(&mut seed) - 0.5));
    }
    mesh
}

#[test]
fn a_smooth_fit_that_strays_tries_the_facets_even_without_sharp_edges() {
    let (fit, smooth) = with_and_without_candidate(&jolted_torus(), 100);
    let limit = 0.005 * fit.component.bounds_diagonal();
    let choice = fit
        .faceted
        .expect("a smooth fit past the stray bound tries the candidate");
    let smooth_stray = smooth.stray.expect("measured");
    let (rms, _) = rms_max(&fit.data, &control_mesh(&fit));
    println!(
        "jolted torus, {} points, {} controls: smooth RMS {:.3e} stray {smooth_stray:.3e}; \
         faceted RMS {rms:.3e} (own feet {:.3e}) stray {:.3e}; bound {limit:.3e}",
        fit.data.len(),
        fit.controls.len(),
        smooth.rms,
        choice.faceted_rms,
        choice.faceted_stray
    );
    assert!(
        smooth_stray > limit,
        "the smooth fit stays within the bound"
    );
    assert_eq!(
        choice.smooth_rms, smooth.rms,
        "the same smooth fit was compared"
    );
    assert!(choice.kept_faceted, "{choice:?}");
    assert!(is_faceted(fit.surface.faces(), fit.surface.crease_edges()));
    // The kept surface measured independently (the data to its control mesh, which it
    // is) against the smooth fit's own RMS to its foot points, which is at least its
    // nearest-point RMS: the faceted surface comes 26 % nearer, far more than the two
    // measures of one surface differ (a few percent on the smooth fits measured).
    assert!(
        rms < smooth.rms,
        "faceted {rms} against smooth {}",
        smooth.rms
    );
    assert!(choice.faceted_stray < smooth_stray);
}

/// The farthest point of a faceted fit's surface (its control mesh) from the data mesh,
/// on an 8-segment lattice of every face: measured here, not by the fit.
fn faceted_stray(fit: &ObjectFit) -> f64 {
    let data = MeshDistance::new(&fit.component);
    let mut worst = 0.0f64;
    for t in fit.surface.faces() {
        let [a, b, c] = t.map(|v| fit.controls[v as usize]);
        for i in 0..=8 {
            for j in 0..=8 - i {
                let (u, v) = (i as f64 / 8.0, j as f64 / 8.0);
                let p = a * (1.0 - u - v) + b * u + c * v;
                worst = worst.max(data.distance(p).expect("a finite distance"));
            }
        }
    }
    worst
}

/// Where neither the smooth fits of the budget's growth nor the faceting at the kept
/// fit's count come within the stray bound, the faceted last resort doubles the controls
/// until a faceting does, and the bound holds. The jolted torus at 100 controls: the
/// faceting at 220 strays 4.4e-2 past a 2.0e-2 bound, and the smooth fit strays 7.0e-2
/// even with a control at every one of its 384 vertices (between coarse vertices a
/// smooth surface leaves the facets whatever its count). Without the growth
/// (`stray_budget_steps` 0) the budget holds instead and the surface strays.
#[test]
fn the_stray_bound_holds_by_facets_where_no_smooth_fit_can() {
    let mesh = jolted_torus();
    let opts = ObjectOptions {
        target_controls: Some(100),
        ..ObjectOptions::default()
    };
    let fit = fit_object(&mesh, &opts).expect("fitted");
    let limit = 0.005 * fit.component.bounds_diagonal();
    let budgets = &fit.stray_budgets;
    let last = budgets.last().expect("an escalation");
    assert!(last.kept && last.faceted, "{budgets:?}");
    assert_eq!(budgets.iter().filter(|b| b.kept).count(), 1, "{budgets:?}");
    assert_eq!(fit.controls.len(), last.controls);
    assert!(is_faceted(fit.surface.faces(), fit.surface.crease_edges()));
    let stray = faceted_stray(&fit);
    println!(
        "jolted torus: {} controls faceted, stray {stray:.3e} (bound {limit:.3e}); tries {budgets:?}",
        fit.controls.len()
    );
    assert!(stray <= limit, "{stray} past {limit}");
    assert!(
        budgets.iter().all(|b| b.kept || b.stray > limit),
        "{budgets:?}"
    );

    let held = fit_object(
        &mesh,
        &ObjectOptions {
            stray_budget_steps: 0,
            ..opts
        },
    )
    .expect("fitted");
    assert!(held.stray_budgets.iter().all(|b| !b.faceted));
    assert!(held.stray.is_some_and(|s| s > limit), "{:?}", held.stray);
}

/// A one-row strip of long triangles: every face stands on one side's boundary by an edge
/// and touches the other side's by its third corner only.
fn long_strip(quads: usize) -> (TriMesh, Vec<SurfaceParam>) {
    let bottom = |i: usize| DVec3::new(10.0 * i as f64, 0.0, 0.0);
    let top = |i: usize| DVec3::new(10.0 * i as f64 + 5.0, 1.0, 0.0);
    let positions: Vec<DVec3> = (0..=quads)
        .map(bottom)
        .chain((0..=quads).map(top))
        .collect();
    let (b, t) = (|i: usize| i as u32, |i: usize| (quads + 1 + i) as u32);
    let mut triangles = Vec::new();
    for i in 0..quads {
        triangles.push([b(i), b(i + 1), t(i)]);
        triangles.push([t(i), b(i + 1), t(i + 1)]);
    }
    // Each vertex starts at a corner of a face whose boundary edge lies across from it
    // (a top vertex on the face below it, a bottom vertex on the face above it), as a
    // foot search on such a mesh may leave it.
    let corner = |face: usize, k: usize| {
        let mut w = [0.0; 3];
        w[k] = 1.0;
        SurfaceParam {
            face: face as u32,
            u: w[0],
            v: w[1],
        }
    };
    let params = (0..=quads)
        .map(|i| {
            if i == 0 {
                corner(0, 0)
            } else {
                corner(2 * i - 1, 1)
            }
        })
        .chain((0..=quads).map(|i| {
            if i == quads {
                corner(2 * quads - 1, 2)
            } else {
                corner(2 * i, 2)
            }
        }))
        .collect();
    (TriMesh::new(positions, triangles), params)
}

#[test]
fn a_faceted_surface_through_the_data_holds_its_rim_feet_where_they_are() {
    let (strip, params) = long_strip(12);
    let mut creases: Vec<[u32; 2]> = strip
        .triangles
        .iter()
        .flat_map(|t| [0, 1, 2].map(|k| [t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])]))
        .collect();
    creases.sort_unstable();
    creases.dedup();
    let opts = ObjectOptions {
        rounds: 0,
        smoothing: 0.0,
        ..ObjectOptions::default()
    };
    let fit =
        fit_on_creased_control_mesh(strip.clone(), strip.clone(), &creases, params, None, &opts)
            .expect("the strip fits");
    // The surface is its control mesh (every vertex a corner of its creases) ...
    assert!(gap_to_control_mesh(&fit) < 1e-9);
    // ... and the point fit puts it on the strip, every data point on it: feet held
    // across their faces on the other side's boundary (the strip's height away) would
    // have pulled the controls there.
    let moved = fit
        .controls
        .iter()
        .zip(&strip.positions)
        .map(|(c, p)| c.distance(*p))
        .fold(0.0, f64::max);
    assert!(moved < 1e-9, "a control moved by {moved}");
    assert!(fit.max < 1e-9, "max {} rms {}", fit.max, fit.rms);
}
