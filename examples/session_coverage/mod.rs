//! bun_zipper against the object session's surface where the five scans cover it, for
//! `object_session`: how much lies within 0.5 mm, inside the scans' rim, and whose miss
//! each miss is (no view's data, the merge's, or the fit's).

use super::{distances_beyond, row, used_vertices, Scan};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::merge::merge;
use trispline::pipeline::object_session::{distance_stats, ObjectSession, SessionOptions};
use trispline::{DVec3, TriMesh};

/// bun_zipper's vertices where some scan covers them (a scan point within 1 mm): the share
/// within 0.5 mm of the surface and the largest distance.
pub fn coverage_check(scans: &[Scan], surface: &TriMesh, zipper: &TriMesh) -> Vec<DVec3> {
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
    let near = |p: DVec3| -> Vec<DVec3> {
        let (a, b, c) = key(p);
        let mut found = Vec::new();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(v) = buckets.get(&(a + dx, b + dy, c + dz)) {
                        found.extend(v.iter().copied().filter(|q| q.distance(p) <= COVER));
                    }
                }
            }
        }
        found
    };
    let covered_at = |p: DVec3| !near(p).is_empty();
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
    // Inside the data's rim: scan points all around the vertex in its tangent plane (no
    // angular gap of half a turn). A vertex within 1 mm of a scan point but beyond the
    // scans' rim lies where the surface, stopping at the rim, cannot be.
    let normals = zipper.vertex_normals();
    let (mut inside, mut inside_within, mut inside_max) = (0, 0, 0.0f64);
    let mut missed = Vec::new();
    for (p, n) in zipper.positions.iter().zip(&normals) {
        let around = near(*p);
        if around.is_empty() || !surrounded(*p, *n, &around) {
            continue;
        }
        let Some(d) = query.distance(*p) else {
            continue;
        };
        inside += 1;
        inside_within += usize::from(d <= 5e-4);
        inside_max = inside_max.max(d);
        if d > 5e-4 {
            missed.push(*p);
        }
    }
    println!(
        "  of which inside the scans' rim ({inside} vertices): {:.2} % within 0.5 mm, max {:.3} mm",
        100.0 * inside_within as f64 / inside.max(1) as f64,
        inside_max * 1e3
    );
    misses_by_scan(scans, &missed);
    on_scan_surfaces(scans, &query, zipper);
    missed
}

/// The registered scans' own meshes, for distances to what each view measured.
fn registered_scans(scans: &[Scan]) -> Vec<TriMesh> {
    scans
        .iter()
        .map(|(_, mesh, t, _)| {
            let mut moved = mesh.clone();
            for p in &mut moved.positions {
                *p = t.apply(*p);
            }
            moved
        })
        .collect()
}

/// The strictest reading of "where the scans cover it": bun_zipper's vertices that some
/// scan's own triangles pass within 0.5 mm of (a view measured the surface there, not
/// beside it across a rim or a thin part), and the share of them within 0.5 mm of the
/// surface.
fn on_scan_surfaces(scans: &[Scan], surface: &MeshDistance, zipper: &TriMesh) {
    let moved = registered_scans(scans);
    let registered: Vec<MeshDistance> = moved.iter().map(MeshDistance::new).collect();
    let (mut on, mut within, mut worst) = (0usize, 0usize, 0.0f64);
    let mut misses = String::new();
    for p in &zipper.positions {
        let nearest = registered
            .iter()
            .filter_map(|m| m.distance(*p))
            .fold(f64::INFINITY, f64::min);
        if nearest > 5e-4 {
            continue;
        }
        let Some(d) = surface.distance(*p) else {
            continue;
        };
        on += 1;
        within += usize::from(d <= 5e-4);
        worst = worst.max(d);
        if d > 5e-4 {
            misses.push_str(&format!("{} {} {} {d} {nearest}\n", p.x, p.y, p.z));
        }
    }
    if let Ok(file) = std::env::var("OBJ_SESSION_DUMP") {
        let file = format!("{file}.strict");
        if let Err(e) = std::fs::write(&file, misses) {
            eprintln!("could not write {file}: {e}");
        }
    }
    println!(
        "  on a scan's own surface (its triangles within 0.5 mm; {on} vertices): {:.2} % within \
         0.5 mm, max {:.3} mm",
        100.0 * within as f64 / on.max(1) as f64,
        worst * 1e3
    );
}

/// Whether any scan's own surface (its triangles, registered) passes within 0.5 mm of each
/// bun_zipper vertex the surface misses: where none does, VRIP's ten views put the surface
/// where these five views have no data, and no fit of them can reach it.
fn misses_by_scan(scans: &[Scan], missed: &[DVec3]) {
    let moved = registered_scans(scans);
    let registered: Vec<MeshDistance> = moved.iter().map(MeshDistance::new).collect();
    let nearest_scan = |p: DVec3| {
        registered
            .iter()
            .filter_map(|m| m.distance(p))
            .fold(f64::INFINITY, f64::min)
    };
    let near: Vec<f64> = missed.iter().map(|p| nearest_scan(*p)).collect();
    let supported = near.iter().filter(|&&d| d <= 5e-4).count();
    println!(
        "  its {} misses: {supported} have a scan's own surface within 0.5 mm (the merge's \
         or the fit's), {} have none (no view of these five puts data there)",
        missed.len(),
        missed.len() - supported
    );
}

/// Whether `points` surround `p` in the plane of `normal`: their directions from `p`
/// leave no angular gap of half a turn or more.
fn surrounded(p: DVec3, normal: DVec3, points: &[DVec3]) -> bool {
    let e1 = normal.any_orthonormal_vector();
    let e2 = normal.cross(e1);
    let mut angles: Vec<f64> = points
        .iter()
        .map(|q| *q - p)
        .filter(|d| d.length() > 1e-9)
        .map(|d| d.dot(e2).atan2(d.dot(e1)))
        .collect();
    if angles.len() < 3 {
        return false;
    }
    angles.sort_by(f64::total_cmp);
    let wrap = angles[0] + std::f64::consts::TAU - angles[angles.len() - 1];
    let gap = angles.windows(2).map(|w| w[1] - w[0]).fold(wrap, f64::max);
    gap < std::f64::consts::PI
}

/// Which of bun_zipper's vertices the merged data (what the surface is fitted to) already
/// misses, and which only the surface misses: a vertex far from the surface but near the
/// merged mesh is the fit's fault, one far from both is the merge's.
pub fn merged_coverage(
    session: &ObjectSession,
    opts: &SessionOptions,
    surface: &TriMesh,
    zipper: &TriMesh,
    missed_inside: &[DVec3],
) {
    let Some(cell) = session.cell() else {
        return;
    };
    let all: Vec<_> = session.scans().values().map(|s| &s.samples).collect();
    let merged = merge(&all, cell, &opts.merge).mesh;
    let to_merged = MeshDistance::new(&merged);
    let to_surface = MeshDistance::new(surface);
    let to_zipper = MeshDistance::new(zipper);
    let mut merge_gaps: Vec<f64> = missed_inside
        .iter()
        .map(|p| to_merged.distance(*p).unwrap_or(f64::INFINITY))
        .filter(|&d| d > 5e-4)
        .collect();
    merge_gaps.sort_by(f64::total_cmp);
    let merge_misses = merge_gaps.len();
    if let Ok(path) = std::env::var("OBJ_SESSION_DUMP") {
        // The misses inside the rim with their distances to the merged data and the surface.
        let rows: String = missed_inside
            .iter()
            .map(|p| {
                let dm = to_merged.distance(*p).unwrap_or(f64::INFINITY);
                let ds = to_surface.distance(*p).unwrap_or(f64::INFINITY);
                format!("{} {} {} {dm} {ds}\n", p.x, p.y, p.z)
            })
            .collect();
        let _ = std::fs::write(format!("{path}.inside"), rows);
    }
    println!(
        "  of the misses inside the rim, {merge_misses} are over 0.5 mm from the merged data \
         as well (the merge's; median {:.2} mm, max {:.2} mm from it), {} only from the \
         surface (the fit's)",
        merge_gaps.get(merge_misses / 2).map_or(0.0, |d| d * 1e3),
        merge_gaps.last().map_or(0.0, |d| d * 1e3),
        missed_inside.len() - merge_misses
    );
    let (mut fit_only, mut both, mut merge_only, mut near) = (0, 0, 0, 0);
    let mut dump = String::new();
    for p in &zipper.positions {
        let (Some(dm), Some(ds)) = (to_merged.distance(*p), to_surface.distance(*p)) else {
            continue;
        };
        if dm > 2e-3 {
            continue; // not covered by the merged data at all
        }
        near += 1;
        match (dm > 5e-4, ds > 5e-4) {
            (false, true) => fit_only += 1,
            (true, true) => {
                both += 1;
                dump += &format!("{} {} {} {dm} {ds}\n", p.x, p.y, p.z);
            }
            (true, false) => merge_only += 1,
            _ => {}
        }
    }
    if let Ok(path) = std::env::var("OBJ_SESSION_DUMP") {
        let _ = std::fs::write(path, dump);
    }
    let stray = distances_beyond(&surface.positions, &to_merged, 5e-4).len();
    let zipper_off = distances_beyond(&merged.positions, &to_zipper, 5e-4).len();
    println!(
        "bun_zipper vertices within 2 mm of the merged mesh: {near}; over 0.5 mm from the surface only: {fit_only}, from both: {both}, from the merged mesh only: {merge_only}"
    );
    println!(
        "surface vertices over 0.5 mm from the merged mesh: {stray} of {}; merged vertices over 0.5 mm from bun_zipper: {zipper_off} of {}",
        surface.positions.len(),
        merged.positions.len()
    );
}
