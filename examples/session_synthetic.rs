//! An object session on any model, scanned view by view in code: the session's quality on
//! shapes nobody tuned it on, against the model itself (the ground truth a real scan
//! session never has).
//!
//!     cargo run --release --example session_synthetic -- MODEL [VIEWS [NOISE [MISREG]]]
//!
//! Each view is an orthographic range scan of MODEL (a 400 x 400 grid, as a structured-light
//! scanner takes it): a depth buffer of the faces that face the camera at more than 10
//! degrees from grazing, Gaussian noise of NOISE (default 3e-4) times the bounding-box
//! diagonal along the view, the grid triangulated where neighbouring depths agree. Views
//! look from VIEWS (default 6) directions around the model, alternately 25 degrees above
//! and below its equator. Each scan is given in its scanner's frame with a registration
//! off by MISREG (default 2e-4) of the diagonal in translation and as much rotation at the
//! diagonal's length (real registrations are off by tens of micrometres on the bunny's
//! 0.2 m diagonal: 1e-4 to 3e-4).
//!
//! Per update: wall time, path, controls, merged points, the fit's RMS to the merged data,
//! the merged pieces left out of the surface (report.json's `dropped`: an early view of a
//! shape with handles falls into pieces, and the session fits the largest), and against
//! the model: the RMS and 95th percentile of the model's vertices that some
//! scan so far sees (a scan point within two pixels) to the surface, and the share within
//! 1e-3 of the diagonal. At the end the same for a quadric decimation of the merged mesh
//! to as many vertices as the surface has controls (the user's "fewer numbers, same shape"
//! alternative), and how far the surface strays from the model (its tessellation's
//! vertices to the model, 95th percentile and max). `SYNTH_CELL_EDGES=E` sets the merge
//! cell to E median scan edges (`[object.merge] cell_edges`); `SYNTH_OVERHANG_CELLS=C` keeps
//! merged vertices up to C cells past the data's rim (`rim_overhang_cells`); `SYNTH_WORST=1` lists the
//! 20 covered model vertices farthest from the surface.

use glam::DMat3;
use std::time::Instant;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::clean::CleanOptions;
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::point_grid::PointGrid;
use trispline::mesh::rigid::RigidTransform;
use trispline::mesh::simplify::baseline::decimation_baselines;
use trispline::pipeline::merge::merge;
use trispline::pipeline::object::fitted_component;
use trispline::pipeline::object_session::{surface_mesh, ObjectSession, SessionOptions};
use trispline::{DVec3, TriMesh};

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Pixels along each side of a view.
const GRID: usize = 400;
/// Faces seen closer to grazing than this cosine are not scanned.
const GRAZING_COS: f64 = 0.17;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: session_synthetic MODEL [VIEWS [NOISE [MISREG]]]");
        std::process::exit(2);
    };
    let number = |k: usize, default: f64| {
        args.get(k)
            .and_then(|s| s.parse::<f64>().ok())
            .unwrap_or(default)
    };
    let views = number(2, 6.0).max(1.0) as usize;
    let (noise, misregistration) = (number(3, 3e-4), number(4, 2e-4));
    let model = match read_mesh_file(std::path::Path::new(path), &LoadOptions::default()) {
        Ok(l) => l.mesh,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let diagonal = model.bounds_diagonal();
    println!(
        "{path}: {} vertices, diagonal {diagonal:.4e}; {views} views, noise {noise:.1e}, \
         misregistration {misregistration:.1e} of the diagonal",
        model.positions.len()
    );
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let scans: Vec<Scan> = (0..views)
        .map(|k| scan_view(&model, k, views, [noise, misregistration], &mut seed))
        .collect();
    let truth = MeshDistance::new(&model);
    let mut opts = SessionOptions {
        measure_scans: false,
        ..Default::default()
    };
    // The merge cell in median scan edges (`[object.merge] cell_edges`), for comparisons.
    if let Some(edges) = std::env::var("SYNTH_CELL_EDGES")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
    {
        opts.merge.cell_edges = edges;
    }
    // How far past the data's rim a merged vertex is kept, in cells
    // (`[object.merge] rim_overhang_cells`), for comparisons.
    if let Some(cells) = std::env::var("SYNTH_OVERHANG_CELLS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
    {
        opts.merge.rim_overhang_cells = cells;
    }
    let mut session = ObjectSession::new(opts.clone());
    let mut seen: Vec<DVec3> = Vec::new();
    let mut last = None;
    for (k, scan) in scans.iter().enumerate() {
        let id = format!("view{k}");
        let t = Instant::now();
        let update = match session.add_scan(&id, &scan.mesh, scan.registration) {
            Ok(u) => u,
            Err(e) => {
                println!("{id}: refused: {e}");
                continue;
            }
        };
        let wall = t.elapsed().as_secs_f64() * 1e3;
        seen.extend(scan.object_points.iter().copied());
        let surface = surface_mesh(&update.fit);
        let covered = covered_vertices(&model, &seen, 2.0 * scan.pixel);
        let against = Against::of(&covered, &surface, diagonal);
        println!(
            "+{id:6} {:>5} scan points {wall:7.0} ms  path {:6}  controls {:5}  merged {:6}  \
             fit rms {:.3e}  | model ({} covered vertices) to surface: {}",
            scan.mesh.positions.len(),
            update.path,
            update.fit.controls.len(),
            update.merged_vertices,
            rms(&update.fit.geometric_errors),
            covered.len(),
            against.row()
        );
        let dropped = &update.outputs.report["dropped"];
        if dropped.as_object().is_some_and(|d| !d.is_empty()) || dropped.is_array() {
            println!("        dropped: {dropped}");
        }
        last = Some((update, covered));
    }
    let Some((update, covered)) = last else {
        return;
    };
    let surface = surface_mesh(&update.fit);
    let far: Vec<f64> = surface
        .positions
        .iter()
        .filter_map(|p| truth.distance(*p))
        .collect();
    let (p95, max) = (
        percentile(&far, 0.95),
        far.iter().fold(0.0f64, |a, &b| a.max(b)),
    );
    println!(
        "surface to the model: p95 {:.2e} ({:.3} % of the diagonal), max {:.2e} ({:.3} %)",
        p95,
        100.0 * p95 / diagonal,
        max,
        100.0 * max / diagonal
    );
    let Some(cell) = session.cell() else {
        return;
    };
    println!(
        "merge cell {cell:.3e} ({:.3} % of the diagonal)",
        100.0 * cell / diagonal
    );
    let all: Vec<_> = session.scans().values().map(|s| &s.samples).collect();
    let merged = merge(&all, cell, &opts.merge);
    // The part the fit takes: the merge's cleaned largest component.
    let Some(fitted) = fitted_component(&merged.mesh, &CleanOptions::default()) else {
        println!("the merged mesh has no component to fit");
        return;
    };
    let target = update.fit.controls.len();
    for (name, decimated) in ["guarded", "plain"]
        .iter()
        .zip(decimation_baselines(&fitted, target))
    {
        match decimated {
            Ok(d) => println!(
                "quadric decimation of the merged mesh ({name}, {} vertices): model to it: {}",
                d.mesh.positions.len(),
                Against::of(&covered, &d.mesh, diagonal).row()
            ),
            Err(e) => println!("quadric decimation ({name}): {e}"),
        }
    }
    println!(
        "the merged mesh's fitted component ({} vertices): model to it: {}",
        fitted.positions.len(),
        Against::of(&covered, &fitted, diagonal).row()
    );
    if std::env::var("SYNTH_WORST").is_ok() {
        worst(&covered, &surface, &fitted);
    }
}

/// The 20 covered model vertices farthest from the surface, with their distance to the
/// merged data: where the session misses the model, and whether the merge does too.
fn worst(covered: &[DVec3], surface: &TriMesh, merged: &TriMesh) {
    let (to_surface, to_merged) = (MeshDistance::new(surface), MeshDistance::new(merged));
    let mut d: Vec<(f64, DVec3)> = covered
        .iter()
        .filter_map(|p| to_surface.distance(*p).map(|x| (x, *p)))
        .collect();
    d.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (x, p) in d.iter().take(20) {
        println!(
            "  {p:.4?}: {x:.3e} from the surface, {:.3e} from the merged data",
            to_merged.distance(*p).unwrap_or(f64::NAN)
        );
    }
}

/// One view: the scan in its scanner's frame, the registration given with it (off by the
/// misregistration), and the points of its triangles where they truly lie.
struct Scan {
    mesh: TriMesh,
    registration: RigidTransform,
    object_points: Vec<DVec3>,
    pixel: f64,
}

/// A standard normal number (Box-Muller on xorshift draws).
fn gaussian(seed: &mut u64) -> f64 {
    let mut uniform = || {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        ((*seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let (a, b) = (uniform(), uniform());
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

/// The `k`-th of `views` views (see the module docs).
fn scan_view(
    model: &TriMesh,
    k: usize,
    views: usize,
    [noise, misreg]: [f64; 2],
    seed: &mut u64,
) -> Scan {
    let diagonal = model.bounds_diagonal();
    let azimuth = std::f64::consts::TAU * k as f64 / views as f64;
    let elevation = if k.is_multiple_of(2) { 25f64 } else { -25f64 }.to_radians();
    let toward = DVec3::new(
        elevation.cos() * azimuth.cos(),
        elevation.cos() * azimuth.sin(),
        elevation.sin(),
    );
    let e1 = toward.any_orthonormal_vector();
    let e2 = toward.cross(e1);
    let depth = depth_buffer(model, [e1, e2, toward]);
    let pixel = depth.pixel;
    // Scan points in the model's frame, noisy along the view.
    let mut index = vec![u32::MAX; GRID * GRID];
    let mut object_points = Vec::new();
    let mut noisy = Vec::new();
    for (cell, d) in depth.depth.iter().enumerate() {
        let Some(d) = *d else { continue };
        let (i, j) = (cell % GRID, cell / GRID);
        let p = depth.origin
            + e1 * ((i as f64 + 0.5) * pixel)
            + e2 * ((j as f64 + 0.5) * pixel)
            + toward * d;
        index[cell] = object_points.len() as u32;
        object_points.push(p);
        noisy.push(p + toward * (noise * diagonal * gaussian(seed)));
    }
    let triangles = grid_triangles(&index, &depth.depth, 3.0 * pixel);
    // A point in no triangle (steep ground between silhouette pixels) is no scan data:
    // the session takes a scan's triangles; it does not cover the model either.
    let mut used = vec![false; object_points.len()];
    for t in &triangles {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let object_points: Vec<DVec3> = object_points
        .iter()
        .zip(&used)
        .filter(|(_, &u)| u)
        .map(|(p, _)| *p)
        .collect();
    // The scanner's frame: the view along its -z, the model's centre at its origin.
    let (lo, hi) = model.positions.iter().fold(
        (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let centre = 0.5 * (lo + hi);
    let to_scanner = DMat3::from_cols(e1, e2, toward).transpose();
    let positions = noisy.iter().map(|p| to_scanner * (*p - centre)).collect();
    // The registration back, off by a small rotation and translation.
    let axis = DVec3::new(gaussian(seed), gaussian(seed), gaussian(seed)).normalize_or_zero();
    let wobble = DMat3::from_axis_angle(axis, misreg);
    let shift = DVec3::new(gaussian(seed), gaussian(seed), gaussian(seed)).normalize_or_zero()
        * (misreg * diagonal);
    let registration = RigidTransform {
        rotation: wobble * to_scanner.transpose(),
        translation: centre + shift,
    };
    Scan {
        mesh: TriMesh::new(positions, triangles),
        registration,
        object_points,
        pixel,
    }
}

/// A view's depths: per pixel the depth (along the view, toward the camera) of the
/// nearest face facing the camera, `None` where none is.
struct DepthBuffer {
    depth: Vec<Option<f64>>,
    origin: DVec3,
    pixel: f64,
}

fn depth_buffer(model: &TriMesh, [e1, e2, toward]: [DVec3; 3]) -> DepthBuffer {
    let projected: Vec<DVec3> = model
        .positions
        .iter()
        .map(|p| DVec3::new(p.dot(e1), p.dot(e2), p.dot(toward)))
        .collect();
    let (lo, hi) = projected.iter().fold(
        (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let extent = (hi.x - lo.x).max(hi.y - lo.y);
    let pixel = extent * 1.02 / GRID as f64;
    let (u0, v0) = (lo.x - 0.01 * extent, lo.y - 0.01 * extent);
    let mut depth: Vec<Option<f64>> = vec![None; GRID * GRID];
    for t in &model.triangles {
        let [a, b, c] = t.map(|v| projected[v as usize]);
        let normal = (b - a).cross(c - a);
        let length = normal.length();
        if length <= 0.0 || normal.z / length < GRAZING_COS {
            continue;
        }
        let to_pixel = |p: DVec3| ((p.x - u0) / pixel - 0.5, (p.y - v0) / pixel - 0.5);
        let (pa, pb, pc) = (to_pixel(a), to_pixel(b), to_pixel(c));
        let area = (pb.0 - pa.0) * (pc.1 - pa.1) - (pc.0 - pa.0) * (pb.1 - pa.1);
        let i0 = pa.0.min(pb.0).min(pc.0).ceil().max(0.0) as usize;
        let i1 = (pa.0.max(pb.0).max(pc.0).floor() as i64).min(GRID as i64 - 1);
        let j0 = pa.1.min(pb.1).min(pc.1).ceil().max(0.0) as usize;
        let j1 = (pa.1.max(pb.1).max(pc.1).floor() as i64).min(GRID as i64 - 1);
        // The margin keeps every face on the grid; a face off it has nothing to draw.
        let (Ok(i1), Ok(j1)) = (usize::try_from(i1), usize::try_from(j1)) else {
            continue;
        };
        for j in j0..=j1 {
            for i in i0..=i1 {
                let (x, y) = (i as f64, j as f64);
                let wa = ((pb.0 - x) * (pc.1 - y) - (pc.0 - x) * (pb.1 - y)) / area;
                let wb = ((pc.0 - x) * (pa.1 - y) - (pa.0 - x) * (pc.1 - y)) / area;
                let wc = 1.0 - wa - wb;
                if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                    continue;
                }
                let z = wa * a.z + wb * b.z + wc * c.z;
                let cell = &mut depth[j * GRID + i];
                if cell.is_none_or(|d| z > d) {
                    *cell = Some(z);
                }
            }
        }
    }
    // Depths in the buffer are along `toward` from the plane through the origin; the
    // pixel centres' in-plane coordinates start at (u0, v0).
    DepthBuffer {
        depth,
        origin: e1 * u0 + e2 * v0,
        pixel,
    }
}

/// Two triangles per grid square whose corners all hold a point, each kept where its
/// corners' depths lie within `jump` of each other (no bridge across a silhouette),
/// counter-clockwise seen from the camera.
fn grid_triangles(index: &[u32], depth: &[Option<f64>], jump: f64) -> Vec<[u32; 3]> {
    let mut triangles = Vec::new();
    let close = |cells: [usize; 3]| {
        let d: Vec<f64> = cells.iter().filter_map(|&c| depth[c]).collect();
        d.len() == 3
            && d.iter().fold(f64::MIN, |a, &b| a.max(b)) - d.iter().fold(f64::MAX, |a, &b| a.min(b))
                <= jump
    };
    for j in 0..GRID - 1 {
        for i in 0..GRID - 1 {
            let c = j * GRID + i;
            let [a, b, d, e] = [c, c + 1, c + GRID, c + GRID + 1];
            for tri in [[a, b, e], [a, e, d]] {
                if close(tri) {
                    triangles.push(tri.map(|x| index[x]));
                }
            }
        }
    }
    triangles
}

/// The model's vertices with a scan point within `radius`.
fn covered_vertices(model: &TriMesh, seen: &[DVec3], radius: f64) -> Vec<DVec3> {
    // Buckets of side `radius`: a scan point within it is among the 27 around a vertex,
    // and the grid proves it the nearest.
    let Some(grid) = PointGrid::new(seen, radius) else {
        return Vec::new();
    };
    model
        .positions
        .iter()
        .copied()
        .filter(|p| {
            grid.nearest(*p)
                .is_some_and(|i| seen[i].distance(*p) <= radius)
        })
        .collect()
}

/// Points' distances to a mesh: RMS, 95th percentile and share within 1e-3 of the diagonal.
struct Against {
    rms: f64,
    p95: f64,
    within: f64,
    diagonal: f64,
}

impl Against {
    fn of(points: &[DVec3], mesh: &TriMesh, diagonal: f64) -> Self {
        let query = MeshDistance::new(mesh);
        let d: Vec<f64> = points.iter().filter_map(|p| query.distance(*p)).collect();
        let near = d.iter().filter(|&&x| x <= 1e-3 * diagonal).count();
        Self {
            rms: rms(&d),
            p95: percentile(&d, 0.95),
            within: near as f64 / d.len().max(1) as f64,
            diagonal,
        }
    }

    fn row(&self) -> String {
        format!(
            "rms {:.3e} ({:.4} % of the diagonal)  p95 {:.3e}  within 0.1 %: {:.2} %",
            self.rms,
            100.0 * self.rms / self.diagonal,
            self.p95,
            100.0 * self.within
        )
    }
}

fn rms(d: &[f64]) -> f64 {
    (d.iter().map(|x| x * x).sum::<f64>() / d.len().max(1) as f64).sqrt()
}

fn percentile(d: &[f64], q: f64) -> f64 {
    if d.is_empty() {
        return 0.0;
    }
    let mut s = d.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}
