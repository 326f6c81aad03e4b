//! Registered scans of one object merged into one mesh: the data the object's surface is
//! fitted to. Pure geometry.
//!
//! Each scan becomes oriented samples (its vertices in the object frame, their normals, a
//! weight that ramps up from the scan's rim as VRIP's does, so that where a view ends the
//! merged surface does not step). All samples define one implicit function: at x, the
//! weighted average over the samples near x of their signed distance along their own
//! normal, `f(x) = sum w_i n_i.(x - p_i) / sum w_i` (Gaussian weights in the distance,
//! only the samples of the sheet the nearest sample is on, so that the two sides of a
//! thin part do not average; Kolluri's and Alexa et al.'s moving-least-squares surfaces).
//! Its zero set is extracted by surface nets on a fixed grid of cells (the origin and
//! the cell size do not depend on the scans' order), one vertex per crossed cell, each
//! projected onto the zero set. So where views overlap, the vertex lies at the weighted
//! mean of the views along the normal: one point per cell whatever the number of views
//! (no double weight), and two views a few tens of micrometres apart give one surface
//! between them, not a ripple between the two.

mod field;
mod holes;
mod implicit;
mod nets;
mod support;
mod types;

use crate::mesh::rigid::RigidTransform;
use crate::TriMesh;
use glam::DVec3;
use rustc_hash::FxHashMap;
use std::collections::VecDeque;

pub use field::MergeField;
pub use types::{CellKey, MergeOptions, Merged, ScanSamples};

/// The samples of a scan mesh (in its own frame) moved by `transform` into the object
/// frame. Vertices no triangle uses, or whose faces have no area, carry no normal and are
/// left out.
pub fn scan_samples(
    mesh: &TriMesh,
    transform: &RigidTransform,
    opts: &MergeOptions,
) -> ScanSamples {
    let n = mesh.positions.len();
    let mut normals = vec![DVec3::ZERO; n];
    let valid = |t: &[u32; 3]| t.iter().all(|&v| (v as usize) < n);
    for t in mesh.triangles.iter().filter(|t| valid(t)) {
        let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
        let area_normal = (b - a).cross(c - a);
        for &v in t {
            normals[v as usize] += area_normal;
        }
    }
    let rings = rings_from_rim(mesh, opts.ramp_rings);
    let mut samples = ScanSamples::default();
    for v in 0..n {
        let (Some(normal), p) = (normals[v].try_normalize(), mesh.positions[v]) else {
            continue;
        };
        if !p.is_finite() {
            continue;
        }
        let ramp = if opts.ramp_rings == 0 {
            1.0
        } else {
            rings[v] as f64 / opts.ramp_rings as f64
        };
        samples.points.push(transform.apply(p));
        samples.normals.push(transform.apply_vector(normal));
        samples
            .weights
            .push(opts.rim_weight + (1.0 - opts.rim_weight) * ramp.min(1.0));
    }
    samples
}

/// Per vertex, its distance in edges from the mesh's rim (vertices on an edge with one
/// face), capped at `cap`.
fn rings_from_rim(mesh: &TriMesh, cap: usize) -> Vec<usize> {
    let n = mesh.positions.len();
    let mut edges: FxHashMap<(u32, u32), u32> = FxHashMap::default();
    for t in mesh
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| (v as usize) < n))
    {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut ring = vec![cap; n];
    let mut queue = VecDeque::new();
    for (&(a, b), &count) in &edges {
        neighbours[a as usize].push(b);
        neighbours[b as usize].push(a);
        if count == 1 {
            for v in [a, b] {
                if ring[v as usize] != 0 {
                    ring[v as usize] = 0;
                    queue.push_back(v);
                }
            }
        }
    }
    while let Some(v) = queue.pop_front() {
        let next = ring[v as usize] + 1;
        if next >= cap {
            continue;
        }
        for &w in &neighbours[v as usize] {
            if ring[w as usize] > next {
                ring[w as usize] = next;
                queue.push_back(w);
            }
        }
    }
    ring
}

/// Median edge length of a mesh's triangles (0 without triangles).
pub fn median_edge(mesh: &TriMesh) -> f64 {
    let n = mesh.positions.len();
    let mut lengths: Vec<f64> = mesh
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| (v as usize) < n))
        .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
        .map(|(a, b)| mesh.positions[a as usize].distance(mesh.positions[b as usize]))
        .filter(|l| l.is_finite() && *l > 0.0)
        .collect();
    if lengths.is_empty() {
        return 0.0;
    }
    let mid = lengths.len() / 2;
    *lengths.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Merges the samples of every scan on a grid of cell size `cell` (see the module docs).
pub fn merge(scans: &[&ScanSamples], cell: f64, opts: &MergeOptions) -> Merged {
    MergeField::new(cell).update(scans, scans, &[], opts)
}

/// How two merges differ: the cells whose vertex appeared, went, or moved.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct MergeChange {
    /// Vertices in cells that had none before.
    pub added: usize,
    /// Vertices gone from cells that had one.
    pub removed: usize,
    /// Vertices of cells in both that moved by more than `moved_tolerance`.
    pub moved: usize,
    /// Vertices in both that stayed.
    pub kept: usize,
    /// Bounding box (min, max) of the added, removed and moved vertices; `None` if none.
    pub bounds: Option<[DVec3; 2]>,
}

impl MergeChange {
    /// The differences between `before` and `after`; vertices moving less than `tolerance`
    /// count as kept.
    pub fn between(before: &Merged, after: &Merged, tolerance: f64) -> Self {
        let old: FxHashMap<CellKey, DVec3> = before
            .cells
            .iter()
            .copied()
            .zip(before.mesh.positions.iter().copied())
            .collect();
        let mut change = MergeChange::default();
        let grow = |p: DVec3, bounds: &mut Option<[DVec3; 2]>| {
            *bounds = Some(match *bounds {
                None => [p, p],
                Some([lo, hi]) => [lo.min(p), hi.max(p)],
            });
        };
        let mut seen: FxHashMap<CellKey, ()> = FxHashMap::default();
        for (c, p) in after.cells.iter().zip(&after.mesh.positions) {
            seen.insert(*c, ());
            match old.get(c) {
                None => {
                    change.added += 1;
                    grow(*p, &mut change.bounds);
                }
                Some(q) if q.distance(*p) > tolerance => {
                    change.moved += 1;
                    grow(*p, &mut change.bounds);
                }
                Some(_) => change.kept += 1,
            }
        }
        for (c, p) in &old {
            if !seen.contains_key(c) {
                change.removed += 1;
                grow(*p, &mut change.bounds);
            }
        }
        change
    }
}

#[cfg(test)]
mod tests {
    use super::{merge, MergeOptions, ScanSamples};
    use glam::DVec3;

    /// Samples of a sphere of radius `r` (a Fibonacci lattice), outward normals.
    fn sphere(r: f64, n: usize, offset: DVec3) -> ScanSamples {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let mut s = ScanSamples::default();
        for i in 0..n {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rho = (1.0 - y * y).sqrt();
            let a = golden * i as f64;
            let d = DVec3::new(rho * a.cos(), y, rho * a.sin());
            s.points.push(d * r + offset);
            s.normals.push(d);
            s.weights.push(1.0);
        }
        s
    }

    #[test]
    fn a_sampled_sphere_merges_into_a_closed_mesh_on_the_sphere() {
        let s = sphere(1.0, 20_000, DVec3::ZERO);
        let m = merge(&[&s], 0.05, &MergeOptions::default());
        let worst = m
            .mesh
            .positions
            .iter()
            .map(|p| (p.length() - 1.0).abs())
            .fold(0.0, f64::max);
        assert!(worst < 2e-3, "vertex off the sphere by {worst}");
        let stats = crate::mesh::stats::mesh_stats(&m.mesh, 0);
        assert_eq!(stats.boundary_loops, 0, "{stats:?}");
        // Outward: the signed volume is positive.
        let volume: f64 = m
            .mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| m.mesh.positions[v as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        assert!(
            (volume - 4.0 / 3.0 * std::f64::consts::PI).abs() < 0.05,
            "{volume}"
        );
    }

    #[test]
    fn two_offset_views_merge_midway_without_doubling_vertices() {
        let a = sphere(1.0, 20_000, DVec3::ZERO);
        let b = sphere(1.0, 20_000, DVec3::new(0.0, 0.0, 0.004));
        let one = merge(&[&a], 0.05, &MergeOptions::default());
        let two = merge(&[&a, &b], 0.05, &MergeOptions::default());
        // One vertex per crossed cell whatever the number of views.
        let ratio = two.mesh.positions.len() as f64 / one.mesh.positions.len() as f64;
        assert!((0.97..1.03).contains(&ratio), "{ratio}");
        // Each vertex midway between the two spheres (2 mm from each along z at the poles).
        let centre = DVec3::new(0.0, 0.0, 0.002);
        let worst = two
            .mesh
            .positions
            .iter()
            .map(|p| ((*p - centre).length() - 1.0).abs())
            .fold(0.0, f64::max);
        assert!(worst < 2.5e-3, "{worst}");
    }
}
