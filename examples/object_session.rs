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
//!    how much of bun_zipper lies within 0.5 mm of the surface where the scans cover it.
//! 4. The same scans in the reverse order: the two end surfaces' distance.

use std::path::{Path, PathBuf};
use trispline::io::registration::registration_for;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::rigid::RigidTransform;
use trispline::pipeline::object_session::{
    distance_stats, surface_mesh, surface_points_at_data, DistanceStats, ObjectSession,
    SessionOptions,
};
use trispline::{DVec3, TriMesh};

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

    let opts = SessionOptions {
        measure_scans: false,
        ..Default::default()
    };
    let forward = run(&scans, opts.clone(), "arrival order");
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
    coverage_check(&scans, &surface, &zipper);

    let reversed: Vec<_> = scans.iter().rev().cloned().collect();
    let backward = run(&reversed, opts, "reverse order");
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

fn run(scans: &[Scan], opts: SessionOptions, label: &str) -> trispline::pipeline::PatchFit {
    println!("\n== session, {label}");
    let mut session = ObjectSession::new(opts);
    let mut last = None;
    for (id, mesh, t, _) in scans {
        match session.add_scan(id, mesh, *t) {
            Ok(u) => {
                let rms = u.fit.geometric_rms();
                let session = &u.outputs.report["session"];
                println!(
                    "+{id:7} {:7.0} ms (merge {:5.0}, fit {:6.0}, outputs {:5.0})  path {:6}  views {:3.0} deg  warm {:5}  controls {:5}  merged {:6}  rms {:5.1} um  changed +{} -{} ~{} ={}",
                    u.times.total_ms,
                    u.times.merge_ms,
                    u.times.fit_ms,
                    u.times.outputs_ms,
                    u.path,
                    session["view_spread_deg"].as_f64().unwrap_or(f64::NAN),
                    u.fit.warm_start,
                    u.fit.controls.len(),
                    u.merged_vertices,
                    um(rms),
                    u.change.added,
                    u.change.removed,
                    u.change.moved,
                    u.change.kept,
                );
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
        Some(f) => f,
        None => std::process::exit(1),
    }
}

/// bun_zipper's vertices where some scan covers them (a scan point within 1 mm): the share
/// within 0.5 mm of the surface and the largest distance.
fn coverage_check(scans: &[Scan], surface: &TriMesh, zipper: &TriMesh) {
    const COVER: f64 = 1e-3;
    let key = |p: DVec3| {
        let q = (p / COVER).floor();
        (q.x as i64, q.y as i64, q.z as i64)
    };
    let mut buckets: std::collections::HashMap<(i64, i64, i64), Vec<DVec3>> = Default::default();
    for (_, mesh, t, _) in scans {
        for v in used_vertices(mesh) {
            let p = t.apply(mesh.positions[v]);
            buckets.entry(key(p)).or_default().push(p);
        }
    }
    let covered_at = |p: DVec3| {
        let (a, b, c) = key(p);
        (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    buckets
                        .get(&(a + dx, b + dy, c + dz))
                        .is_some_and(|v| v.iter().any(|q| q.distance(p) <= COVER))
                })
            })
        })
    };
    let covered: Vec<DVec3> = zipper
        .positions
        .iter()
        .copied()
        .filter(|p| covered_at(*p))
        .collect();
    let query = MeshDistance::new(surface);
    let d: Vec<f64> = covered.iter().filter_map(|p| query.distance(*p)).collect();
    let within = d.iter().filter(|&&x| x <= 5e-4).count();
    let stats = distance_stats(&covered, surface);
    println!(
        "bun_zipper where covered ({} of {} vertices): {:.2} % within 0.5 mm, max {:.3} mm, {}",
        covered.len(),
        zipper.positions.len(),
        100.0 * within as f64 / d.len().max(1) as f64,
        stats.max * 1e3,
        row(&stats)
    );
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
