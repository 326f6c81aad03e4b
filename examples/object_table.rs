//! Whole objects against quadric decimation: each model fitted by `pipeline::object` (the
//! Loop limit surface of a simplified control mesh), compared with the quadric-decimated
//! mesh of as many vertices as there are control points (the simplification the fit
//! started from, a plain QEM decimation).
//!
//! Prints per model: data points, control points (and their share), the fit's RMS / max
//! (data vertices to their foot points on the limit surface), the same measured
//! independently (data vertices to a tessellation of the limit surface, `TESS` segments per
//! control face edge, through `MeshDistance`), the decimated mesh's RMS / max (data vertices
//! to it), the ratio of the RMS values (tessellation over decimation), genus and boundary loops, and the stage times.
//!
//!     cargo run --release --example object_table [-- DATA_DIR [PCT]]

use std::path::PathBuf;
use std::time::Instant;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::simplify::{simplify, SimplifyOptions};
use trispline::pipeline::object::{fit_object, ObjectFit, ObjectOptions};
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::{DVec3, TriMesh};

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Tessellation segments per control face edge for the independent measurement.
const TESS: usize = 8;

fn main() {
    trispline::allocator::keep_freed_memory();
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let pct: f64 = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(5.0);
    let refine_rounds: Option<usize> = std::env::args().nth(3).and_then(|s| s.parse().ok());
    let models = [
        "models/bun_zipper.ply",
        "models/fertility.off",
        "models/decimated-max.obj",
        "models/camelhead.off",
        "models/bun_zipper_res4.ply",
        "range_scans/chin_tri.ply",
        "generated: torus knot",
        "generated: square patch",
    ];
    println!(
        "{:<22} {:>7} {:>6} {:>5} | {:>9} {:>9} | {:>9} {:>9} | {:>6} {:>9} {:>9} | {:>6} | {:>2} {:>2} | {:>7} | times ms: read clean simplify layout surface first rounds (rounds) refine | fit cpu | irregular before/after, rim corners, sampled faces, refinement controls:rms",
        "model", "data", "ctrl", "%", "fit rms", "fit max", "tess rms", "tess max", "qem V", "qem rms", "qem max", "ratio", "g", "b", "stray%"
    );
    for name in models {
        let path = root.join(name);
        let t = Instant::now();
        let mesh = if name == "generated: torus knot" {
            torus_knot(400, 40, 2e-3)
        } else if name == "generated: square patch" {
            square_patch(120, 2e-4)
        } else {
            match read_mesh_file(&path, &LoadOptions::default()) {
                Ok(l) => l.mesh,
                Err(e) => {
                    println!("{name}: {e}");
                    continue;
                }
            }
        };
        let read_ms = t.elapsed().as_secs_f64() * 1e3;
        let mut opts = ObjectOptions {
            target_controls_pct: pct,
            ..Default::default()
        };
        if let Some(r) = refine_rounds {
            opts.refine.rounds = r;
        }
        // Variants for comparison runs, from the environment.
        let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<f64>().ok());
        if let Some(r) = env("OBJ_LAYOUT_ROUNDS") {
            opts.layout.rounds = r as usize;
        }
        if let Some(s) = env("OBJ_REFINE_SHARE") {
            opts.refine.start_share = s;
        }
        if let Some(l) = env("OBJ_MIN_LOOP") {
            opts.simplify.min_boundary_loop = l as usize;
        }
        if let Some(r) = env("OBJ_INTERMEDIATE_ROUNDS") {
            opts.refine.intermediate_rounds = r as usize;
        }
        if let Some(w) = env("OBJ_WARM_REFINE") {
            opts.refine.warm = w != 0.0;
        }
        if let Some(s) = env("OBJ_SAMPLES") {
            opts.surface_samples = s != 0.0;
        }
        if let Some(r) = env("OBJ_RELAX_STEPS") {
            opts.layout.relax_steps = r as usize;
        }
        let cpu_before = cpu_ms();
        let fit = match fit_object(&mesh, &opts) {
            Ok(f) => f,
            Err(e) => {
                println!("{name}: {e}");
                continue;
            }
        };
        let fit_cpu_ms = cpu_ms() - cpu_before;
        let tess = tessellation(&fit);
        let (tess_rms, tess_max) = rms_max(&fit.data, &tess);
        let (_, stray) = rms_max(&tess.positions, &fit.component);
        let stray_pct = 100.0 * stray / fit.component.bounds_diagonal();
        let inner_pct = 100.0 * interior_stray(&fit, &tess) / fit.component.bounds_diagonal();
        // The baseline: plain quadric decimation (no isotropy term) to the control count.
        let baseline = simplify(
            &fit.component,
            &SimplifyOptions {
                target_vertices: fit.controls.len(),
                ..Default::default()
            },
        );
        let (qem_rms, qem_max, qem_count) = match baseline {
            Ok(b) => {
                let (r, m) = rms_max(&fit.data, &b.mesh);
                (r, m, b.mesh.positions.len())
            }
            Err(e) => {
                println!("{name}: baseline decimation failed: {e}");
                continue;
            }
        };
        let n = fit.data.len();
        let m = fit.controls.len();
        let ts = &fit.times;
        println!(
            "{:<22} {:>7} {:>6} {:>5.2} | {:>9.3e} {:>9.3e} | {:>9.3e} {:>9.3e} | {:>6} {:>9.3e} {:>9.3e} | {:>6.3} | {:>2} {:>2} | {:>7.3} ({:.3} inner) | {:.0} {:.0} {:.0} {:.0} {:.0} {:.0} {:.0} ({}) {:.0} | cpu {:.0} ms | {}/{} c{} s{} {}",
            name.trim_start_matches("models/"),
            n,
            m,
            100.0 * m as f64 / n as f64,
            fit.rms,
            fit.max,
            tess_rms,
            tess_max,
            qem_count,
            qem_rms,
            qem_max,
            tess_rms / qem_rms,
            fit.control_topology.genus,
            fit.control_topology.boundary_loops,
            stray_pct,
            inner_pct,
            read_ms,
            ts.clean_ms,
            ts.simplify_ms,
            ts.layout_ms,
            ts.surface_ms,
            ts.first_fit_ms,
            ts.rounds_ms,
            fit.rounds.len() - 1,
            ts.refine_ms,
            fit_cpu_ms,
            fit.layout.irregular_before,
            fit.layout.irregular_after,
            fit.layout.corners,
            fit.sampled_faces,
            fit.refinement
                .iter()
                .map(|r| format!("{}:{:.3e}", r.controls, r.rms))
                .collect::<Vec<_>>()
                .join(" "),
        );
    }
}

/// CPU time of the process (all threads, user + system) in ms, from /proc (10 ms ticks;
/// NaN elsewhere): on a shared machine the wall-clock stage times measure the neighbours.
fn cpu_ms() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit(')').next().unwrap_or("");
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| {
        fields
            .get(i)
            .and_then(|s| s.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    (tick(11) + tick(12)) * 10.0
}

/// A tube of `radius` 0.25 around a (2, 3) torus knot (major radius 2, minor 0.8), `n`
/// rings of `m` vertices, each vertex moved along its normal by noise of about `noise`
/// (a deterministic hash, not a random generator: the table is reproducible).
fn torus_knot(n: usize, m: usize, noise: f64) -> TriMesh {
    let curve = |t: f64| {
        let r = 2.0 + 0.8 * (3.0 * t).cos();
        DVec3::new(
            r * (2.0 * t).cos(),
            r * (2.0 * t).sin(),
            0.8 * (3.0 * t).sin(),
        )
    };
    let tau = std::f64::consts::TAU;
    let mut positions = Vec::with_capacity(n * m);
    for i in 0..n {
        let t = tau * i as f64 / n as f64;
        let h = 1e-5;
        let tangent = (curve(t + h) - curve(t - h)).normalize();
        let normal = (curve(t + h) - 2.0 * curve(t) + curve(t - h))
            .reject_from(tangent)
            .normalize();
        let binormal = tangent.cross(normal);
        for j in 0..m {
            let a = tau * (j as f64 + 0.5 * (i % 2) as f64) / m as f64;
            let dir = normal * a.cos() + binormal * a.sin();
            let hash = ((i * 7919 + j * 104_729) % 1000) as f64 / 1000.0 - 0.5;
            positions.push(curve(t) + dir * (0.25 + 2.0 * noise * hash));
        }
    }
    let at = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    let mut triangles = Vec::with_capacity(2 * n * m);
    for i in 0..n {
        for j in 0..m {
            if i % 2 == 0 {
                triangles.push([at(i, j), at(i + 1, j), at(i, j + 1)]);
                triangles.push([at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
            } else {
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            }
        }
    }
    TriMesh::new(positions, triangles)
}

/// A square height field of side 0.1 on an `n x n` grid, a smooth bump with noise of about
/// `noise` (a deterministic hash): an open patch whose rim has four right-angled corners.
fn square_patch(n: usize, noise: f64) -> TriMesh {
    let h = 0.1 / (n - 1) as f64;
    let mut positions = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f64 * h, j as f64 * h);
            let hash = ((i * 7919 + j * 104_729) % 1000) as f64 / 1000.0 - 0.5;
            let z = 0.01 * (x * 40.0).sin() * (y * 30.0).cos() + 2.0 * noise * hash;
            positions.push(DVec3::new(x, y, z));
        }
    }
    let at = |i: usize, j: usize| (j * n + i) as u32;
    let mut triangles = Vec::with_capacity(2 * (n - 1) * (n - 1));
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    TriMesh::new(positions, triangles)
}

/// The stray of the tessellation over the control faces with no boundary corner (the
/// tessellation holds `(TESS + 1)(TESS + 2) / 2` vertices per face, in face order).
fn interior_stray(fit: &ObjectFit, tess: &TriMesh) -> f64 {
    let control = fit.control_mesh();
    let Ok(topo) = trispline::mesh::topology::Topology::from_mesh(&control) else {
        return f64::NAN;
    };
    let per_face = (TESS + 1) * (TESS + 2) / 2;
    let md = MeshDistance::new(&fit.component);
    let mut worst = 0.0f64;
    for (f, t) in control.triangles.iter().enumerate() {
        if t.iter().any(|&v| topo.boundary[v as usize]) {
            continue;
        }
        for p in &tess.positions[f * per_face..(f + 1) * per_face] {
            worst = worst.max(md.distance(*p).unwrap_or(f64::INFINITY));
        }
    }
    worst
}

/// RMS and max distance of `points` to `mesh`.
fn rms_max(points: &[DVec3], mesh: &TriMesh) -> (f64, f64) {
    let md = MeshDistance::new(mesh);
    let (mut sum, mut max) = (0.0, 0.0f64);
    for p in points {
        let d = md.distance(*p).unwrap_or(f64::INFINITY);
        sum += d * d;
        max = max.max(d);
    }
    ((sum / points.len().max(1) as f64).sqrt(), max)
}

/// Each control face's limit patch on a lattice of `TESS` segments per edge (vertices along
/// shared edges repeated: only distances are measured on it).
fn tessellation(fit: &ObjectFit) -> TriMesh {
    let evaluate = fit.surface.evaluator(&fit.controls);
    let k = TESS;
    // Row j of the lattice holds k + 1 - j points.
    let index = |i: usize, j: usize| j * (2 * k + 3 - j) / 2 + i;
    let per_face = (k + 1) * (k + 2) / 2;
    let mut positions = Vec::with_capacity(fit.surface.domain_face_count() * per_face);
    let mut triangles = Vec::new();
    for f in 0..fit.surface.domain_face_count() {
        let base = positions.len() as u32;
        for j in 0..=k {
            for i in 0..=k - j {
                let p = SurfaceParam {
                    face: f as u32,
                    u: i as f64 / k as f64,
                    v: j as f64 / k as f64,
                };
                positions.push(evaluate(p).position);
            }
        }
        for j in 0..k {
            for i in 0..k - j {
                let a = base + index(i, j) as u32;
                let b = base + index(i + 1, j) as u32;
                let c = base + index(i, j + 1) as u32;
                triangles.push([a, b, c]);
                if i + j + 1 < k {
                    let d = base + index(i + 1, j + 1) as u32;
                    triangles.push([b, d, c]);
                }
            }
        }
    }
    TriMesh::new(positions, triangles)
}
