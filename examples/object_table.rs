//! Whole objects against quadric decimation: each model fitted by `pipeline::object` (the
//! Loop limit surface of a simplified control mesh), compared with the quadric-decimated
//! mesh of as many vertices as there are control points: the better of a plain QEM
//! decimation and one with the simplification's triangle-quality guard.
//!
//! Prints per model: data points, control points (and their share), the fit's RMS / max
//! (data vertices to their foot points on the limit surface), the same measured
//! independently (data vertices to a tessellation of the limit surface, `TESS` segments per
//! control face edge, through `MeshDistance`), the decimated mesh's RMS / max (data vertices
//! to it), the ratio of the RMS values (tessellation over decimation), genus and boundary
//! loops, the stray (how far the tessellation strays from the data, in percent of the
//! diagonal: overall, inside the rim, and the decimated mesh's own on a lattice of its
//! triangles, which says whether the budget lets any mesh stay within the bound), and the
//! stage times; `q1` marks a control mesh simplified without the triangle-quality guard,
//! `f1` a faceted fit kept (`f0` one tried and dropped, with its time; `OBJ_FACETED=0`
//! switches the candidate off).
//!
//!     cargo run --release --example object_table [-- DATA_DIR [PCT [REFINE_ROUNDS]]]
//!
//! `OBJ_MODELS=a,b` keeps the models whose name contains one of the parts; `OBJ_FILES=p,q`
//! adds mesh files by path. `OBJ_REFINE_TOLERANCE=T` caps each refinement round at the
//! faces holding a point farther than T, as `trispline fit` and the daemon do with their
//! error budget's tolerance (the library default has no cap: each round spends its share).
//! `OBJ_TANGENTIAL_EDGE=S` and `OBJ_EDGE_RINGS=R` set the point-to-point share in the band
//! of R rings along the data's rim (`ObjectOptions::tangential_edge`, `edge_rings`).
//! `OBJ_DIAG=1` prints where each fit's error lies (`object_diag`); with it,
//! `OBJ_DUMP_DIST=FILE` writes every data point with its distance to the surface
//! (x y z d), to map where the worst points are.

use std::path::PathBuf;
use std::time::Instant;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::simplify::baseline::decimation_baselines;
use trispline::pipeline::object::{fit_object, ObjectFit, ObjectOptions};
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::{DVec3, TriMesh};

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Tessellation segments per control face edge for the independent measurement.
const TESS: usize = 8;

mod object_diag;

fn main() {
    trispline::allocator::keep_freed_memory();
    trispline::allocator::small_pages_only();
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
        "generated: bumpy blob",
    ];
    println!(
        "{:<22} {:>7} {:>6} {:>5} | {:>9} {:>9} | {:>9} {:>9} | {:>6} {:>9} {:>9} | {:>6} | {:>2} {:>2} | {:>7} | times ms: read clean simplify layout surface first rounds (rounds) refine | fit cpu | irregular before/after, rim corners, crease edges, sampled faces, refinement controls:rms",
        "model", "data", "ctrl", "%", "fit rms", "fit max", "tess rms", "tess max", "qem V", "qem rms", "qem max", "ratio", "g", "b", "stray%"
    );
    let only = std::env::var("OBJ_MODELS").ok();
    // Further models (absolute paths, comma-separated), measured beside the shared ones.
    let extra = std::env::var("OBJ_FILES").unwrap_or_default();
    let extra = extra.split(',').filter(|s| !s.is_empty());
    for name in models.into_iter().chain(extra) {
        if only
            .as_ref()
            .is_some_and(|o| !o.split(',').any(|m| name.contains(m)))
        {
            continue;
        }
        let path = root.join(name);
        let t = Instant::now();
        let mesh = if name == "generated: torus knot" {
            torus_knot(400, 40, 2e-3)
        } else if name == "generated: bumpy blob" {
            bumpy_blob(5, 3e-4)
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
        if let Some(l) = env("OBJ_DOMAIN_LEVELS") {
            opts.domain_levels = l as usize;
        }
        if let Some(s) = env("OBJ_REFINE_SHARE") {
            opts.refine.start_share = s;
        }
        if let Some(q) = env("OBJ_MIN_QUALITY") {
            opts.simplify.min_quality = q;
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
        if let Some(f) = env("OBJ_FACETED") {
            opts.faceted_candidate = f != 0.0;
        }
        if let Some(t) = env("OBJ_TANGENTIAL_EDGE") {
            opts.tangential_edge = t;
        }
        if let Some(r) = env("OBJ_EDGE_RINGS") {
            opts.edge_rings = r as usize;
        }
        if let Some(s) = env("OBJ_SAMPLES") {
            opts.surface_samples = s != 0.0;
        }
        if let Some(r) = env("OBJ_ROUNDS") {
            opts.rounds = r as usize;
        }
        if let Some(g) = env("OBJ_MIN_GAIN") {
            opts.min_gain = g;
        }
        if let Some(s) = env("OBJ_SMOOTHING") {
            opts.smoothing = s;
        }
        if let Some(t) = env("OBJ_TANGENTIAL") {
            opts.tangential = t;
        }
        if let Some(t) = env("OBJ_TANGENTIAL_FLOOR") {
            opts.tangential_floor = t;
        }
        if let Some(t) = env("OBJ_REFINE_TOLERANCE") {
            opts.refine.tolerance = Some(t);
        }
        if let Some(f) = env("OBJ_CURVATURE_FLOOR") {
            // A negative floor: a constant tangential share, no curvature term.
            opts.curvature_floor = (f >= 0.0).then_some(f);
        }
        if let Some(l) = env("OBJ_LIMIT_START") {
            opts.limit_start = l != 0.0;
        }
        if let Some(a) = env("OBJ_CREASE_DEG") {
            opts.crease.angle_deg = a;
        }
        if let Some(r) = env("OBJ_CREASE_RATIO") {
            opts.crease.relative_ratio = r;
        }
        if let Some(r) = env("OBJ_CREASE_MIN_EDGES") {
            opts.crease.min_edges = r as usize;
        }
        if let Some(i) = env("OBJ_ISOTROPY") {
            opts.simplify.isotropy = i;
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
        // The baseline: quadric decimation to the control count, the better of the guarded
        // and the plain one.
        let mut baseline = None;
        for decimated in decimation_baselines(&fit.component, fit.controls.len()) {
            match decimated {
                Ok(b) => {
                    let (r, m) = rms_max(&fit.data, &b.mesh);
                    if baseline.is_none_or(|(best, _, _, _)| r < best) {
                        let (_, s) = rms_max(&face_lattice(&b.mesh, TESS), &fit.component);
                        baseline = Some((r, m, b.mesh.positions.len(), s));
                    }
                }
                Err(e) => println!("{name}: baseline decimation failed: {e}"),
            }
        }
        let Some((qem_rms, qem_max, qem_count, qem_stray)) = baseline else {
            continue;
        };
        let n = fit.data.len();
        let m = fit.controls.len();
        let ts = &fit.times;
        if std::env::var("OBJ_DIAG").is_ok() {
            object_diag::diagnose(&fit, tess_rms);
        }
        println!(
            "{:<22} {:>7} {:>6} {:>5.2} | {:>9.3e} {:>9.3e} | {:>9.3e} {:>9.3e} | {:>6} {:>9.3e} {:>9.3e} | {:>6.3} | {:>2} {:>2} | {:>7.3} ({:.3} inner, qem {:.3}) | {:.0} {:.0} {:.0} {:.0} {:.0} {:.0} {:.0} ({}) {:.0} | cpu {:.0} ms | {}/{} c{} k{} s{} q{} f{} {}",
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
            100.0 * qem_stray / fit.component.bounds_diagonal(),
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
            fit.surface.crease_edges().len(),
            fit.sampled_faces,
            u8::from(fit.layout.quality_guard_dropped),
            match fit.faceted {
                Some(c) if c.kept_faceted => format!("1 ({:.0} ms)", c.ms),
                Some(c) => format!("0 ({:.0} ms)", c.ms),
                None => "-".to_string(),
            },
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

/// A closed blob of radius about 0.05: an icosahedron split 1-to-4 `levels` times, each
/// vertex put at a smooth, bumpy radius (three lobes and a ridge) plus noise of about
/// `noise` (a deterministic hash). Added unseen: its figures were first read after the
/// fit's changes were made.
fn bumpy_blob(levels: usize, noise: f64) -> TriMesh {
    let (corners, mut triangles) = trispline::testdata::icosahedron();
    let mut positions: Vec<DVec3> = corners.into_iter().map(DVec3::normalize).collect();
    for _ in 0..levels {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::with_capacity(4 * triangles.len());
        for tri in &triangles {
            let m = [0, 1, 2].map(|k| {
                let (a, b) = (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]));
                *mid.entry((a, b)).or_insert_with(|| {
                    let p = (positions[a as usize] + positions[b as usize]).normalize();
                    positions.push(p);
                    positions.len() as u32 - 1
                })
            });
            next.push([tri[0], m[0], m[2]]);
            next.push([tri[1], m[1], m[0]]);
            next.push([tri[2], m[2], m[1]]);
            next.push(m);
        }
        triangles = next;
    }
    for (i, p) in positions.iter_mut().enumerate() {
        let lobes = 0.15 * (3.0 * p.x.atan2(p.y)).cos() * (1.0 - p.z * p.z);
        let ridge = 0.1 * (-((p.z - 0.3) / 0.15).powi(2)).exp();
        let hash = ((i * 7919) % 1000) as f64 / 1000.0 - 0.5;
        *p *= 0.05 * (1.0 + lobes + ridge) + 2.0 * noise * hash;
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
    tessellation_at(fit, TESS)
}

/// The points of a lattice of `k` segments per edge on every triangle of `mesh`: where a
/// triangle mesh strays from the data, measured as the fit's tessellation is.
fn face_lattice(mesh: &TriMesh, k: usize) -> Vec<DVec3> {
    let mut points = Vec::new();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
        for j in 0..=k {
            for i in 0..=k - j {
                let (u, v) = (i as f64 / k as f64, j as f64 / k as f64);
                points.push(a * (1.0 - u - v) + b * u + c * v);
            }
        }
    }
    points
}

/// [`tessellation`] at `k` segments per control face edge.
fn tessellation_at(fit: &ObjectFit, k: usize) -> TriMesh {
    let evaluate = fit.surface.evaluator(&fit.controls);
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
