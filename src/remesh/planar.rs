//! Low-distortion planar maps of scan patches.
//!
//! A range scan is a height field seen from the scanner, so its projection along the line of
//! sight is nearly isometric and, where no triangle folds over, a bijection. The direction
//! that folds the fewest triangles (searched around the mean normal) stands in for the line
//! of sight, which the files do not record. That projection is tried first. Folded triangles (overhangs, grazing
//! silhouettes, < 1 % of the triangles) are left out of the mapped mesh, which only serves
//! point location; their vertices keep their projected parameters as data, which needs no
//! injectivity. Holes are closed by ear clipping in the plane (the fans of `fill_holes` where
//! a rim is too long or not simple there). A patch with more folds is no
//! height field: it falls back to Floater's mean-value map with the boundary on a circle,
//! provably bijective, and verified to have no triangle of non-positive area.

use super::param::mean_value_disk;
pub(crate) use super::plane2d::doubled_area;
pub use super::plane2d::folded_triangles;
use super::warp::PlaneWarp;
use super::{FilledPatch, MapFailure, RemeshError};
use crate::mesh::TriMesh;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// An orthonormal frame of the parameter plane, in the input's coordinates. Kept in the
/// warm-start state so that a new version of a patch is projected the same way.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlaneFrame {
    /// A point of the plane (the data's centroid).
    pub origin: DVec3,
    /// First axis.
    pub e1: DVec3,
    /// Second axis.
    pub e2: DVec3,
}

impl PlaneFrame {
    /// Normal = the area-weighted mean of the face normals (for a range scan, close to the
    /// viewing direction); e1 = the principal axis of the vertices within the plane, so the
    /// frame does not spin with small changes of the data.
    pub fn fit(mesh: &TriMesh) -> Option<Self> {
        let p = &mesh.positions;
        let normal: DVec3 = mesh
            .triangles
            .iter()
            .map(|t| {
                let (a, b, c) = (p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
                (b - a).cross(c - a)
            })
            .sum();
        let n = normal.try_normalize()?;
        if p.is_empty() {
            return None;
        }
        let origin = p.iter().copied().sum::<DVec3>() / p.len() as f64;
        let a = n.any_orthonormal_vector();
        let b = n.cross(a);
        // 2x2 covariance in (a, b); its major eigenvector is e1.
        let (mut saa, mut sab, mut sbb) = (0.0, 0.0, 0.0);
        for q in p {
            let d = *q - origin;
            let (x, y) = (d.dot(a), d.dot(b));
            saa += x * x;
            sab += x * y;
            sbb += y * y;
        }
        let angle = 0.5 * (2.0 * sab).atan2(saa - sbb);
        let e1 = a * angle.cos() + b * angle.sin();
        let e2 = n.cross(e1);
        Some(Self { origin, e1, e2 })
    }

    /// A frame whose normal folds the fewest triangles over: range scans are height fields
    /// along the scanner's line of sight, which can be tens of degrees off the mean normal.
    /// Searched on cones around the mean normal (up to 45 degrees, then refined around the
    /// best); ties go to the direction nearest the mean normal.
    pub fn fit_least_folds(mesh: &TriMesh) -> Option<Self> {
        let base = Self::fit(mesh)?;
        let n0 = base.normal();
        let folds = |n: DVec3, limit: usize| -> usize {
            let mut count = 0;
            for t in &mesh.triangles {
                let (a, b, c) = (
                    mesh.positions[t[0] as usize],
                    mesh.positions[t[1] as usize],
                    mesh.positions[t[2] as usize],
                );
                if (b - a).cross(c - a).dot(n) <= 0.0 {
                    count += 1;
                    if count > limit {
                        break;
                    }
                }
            }
            count
        };
        let tilt = |axis: DVec3, tilt_deg: f64, azimuth_deg: f64| -> DVec3 {
            let a = axis.any_orthonormal_vector();
            let b = axis.cross(a);
            let (t, z) = (tilt_deg.to_radians(), azimuth_deg.to_radians());
            (axis * t.cos() + (a * z.cos() + b * z.sin()) * t.sin()).normalize()
        };
        let mut best = (folds(n0, usize::MAX), n0);
        let consider = |n: DVec3, best: &mut (usize, DVec3)| {
            if best.0 == 0 {
                return;
            }
            let f = folds(n, best.0);
            if f < best.0 {
                *best = (f, n);
            }
        };
        for tilt_deg in [8.0, 16.0, 24.0, 32.0, 40.0] {
            for k in 0..12 {
                consider(tilt(n0, tilt_deg, k as f64 * 30.0), &mut best);
            }
        }
        let coarse = best.1;
        for tilt_deg in [2.0, 4.0, 6.0] {
            for k in 0..8 {
                consider(tilt(coarse, tilt_deg, k as f64 * 45.0), &mut best);
            }
        }
        let n = best.1;
        if n == n0 {
            return Some(base);
        }
        // Keep e1 as close to the base frame's principal axis as the new plane allows.
        let e1 = (base.e1 - n * base.e1.dot(n)).try_normalize()?;
        Some(Self {
            origin: base.origin,
            e1,
            e2: n.cross(e1),
        })
    }

    /// Coordinates of p's orthogonal projection in the frame.
    pub fn project(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.e1), d.dot(self.e2))
    }

    /// The plane's unit normal.
    pub fn normal(&self) -> DVec3 {
        self.e1.cross(self.e2)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
/// Which planar map a patch got.
pub enum MapMethod {
    /// Orthogonal projection (folded triangles, if any, left out of the mapped mesh).
    Projection,
    /// Mean-value map with the boundary on a circle (scaled to the patch's size).
    MeanValueDisk,
}

#[derive(Clone, Debug)]
/// A patch mapped onto the plane.
pub struct PlanarMap {
    /// The filled patch as mapped: the projection closes holes by ear clipping in the plane
    /// (no fold by construction) where the fans of `fill_holes` would fold; virtual
    /// vertices left unused stay in place, unreferenced.
    pub mesh: TriMesh,
    /// Plane position of every vertex of `mesh` (real, then virtual).
    pub plane: Vec<DVec2>,
    /// The map used.
    pub method: MapMethod,
    /// Folded triangles of the projection (left out of `mesh` when the projection is used).
    pub folds_projected: usize,
    /// Vertices of those folded triangles: where the map is not to be trusted.
    pub near_fold: Vec<bool>,
    /// The warp applied after the projection (`evened_out`), if any...
    pub warp: Option<PlaneWarp>,
    /// ... and the triangles it folded besides the projection's (left out like those).
    pub folds_warped: usize,
}

impl PlanarMap {
    /// The share of the surface's area (over `mesh`'s triangles) that the map gives less
    /// than `1 / factor` of its share of the plane: where a lattice over the plane puts
    /// fewer than `1 / factor` of the controls the area would get on an even layout.
    pub fn undersampled_share(&self, factor: f64) -> f64 {
        let areas: Vec<(f64, f64)> = self
            .mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.mesh.positions[v as usize]);
                let [p, q, r] = t.map(|v| self.plane[v as usize]);
                (
                    0.5 * (b - a).cross(c - a).length(),
                    0.5 * (q - p).perp_dot(r - p).abs(),
                )
            })
            .collect();
        let (total_3d, total_2d) = areas
            .iter()
            .fold((0.0, 0.0), |(s, t), (a, b)| (s + a, t + b));
        if !(total_3d > 0.0 && total_2d > 0.0) {
            return 0.0;
        }
        let squeezed: f64 = areas
            .iter()
            .filter(|(a3, a2)| factor * a2 / total_2d < a3 / total_3d)
            .map(|(a3, _)| a3)
            .sum();
        squeezed / total_3d
    }
}

/// Longest hole rim closed by ear clipping.
const MAX_EAR_CLIP: usize = 1000;

/// Above this share of folded triangles the patch is no height field over the plane.
const MAX_FOLD_FRACTION: f64 = 0.01;

/// The projection onto `frame` (holes closed in the plane) if it folds little enough,
/// otherwise the mean-value disk map.
pub fn planar_map(patch: &FilledPatch, frame: &PlaneFrame) -> Result<PlanarMap, RemeshError> {
    let plane: Vec<DVec2> = patch
        .mesh
        .positions
        .iter()
        .map(|&p| frame.project(p))
        .collect();
    let mut mesh = patch.mesh.clone();
    mesh.triangles.truncate(patch.real_triangles);
    for hole in &patch.hole_loops {
        let mut poly: Vec<u32> = hole.clone();
        let area: f64 = (0..poly.len())
            .map(|k| plane[poly[k] as usize].perp_dot(plane[poly[(k + 1) % poly.len()] as usize]))
            .sum();
        if area < 0.0 {
            poly.reverse();
        }
        // Ear clipping is quadratic (cubic at worst): long rims keep their fan.
        let clipped = (poly.len() <= MAX_EAR_CLIP).then(|| ear_clip(&poly, &plane));
        match clipped.flatten() {
            Some(tris) => mesh.triangles.extend(tris),
            None => {
                let fan = patch.mesh.triangles[patch.real_triangles..]
                    .iter()
                    .filter(|t| hole.contains(&t[0]) && hole.contains(&t[1]));
                mesh.triangles.extend(fan);
            }
        }
    }
    let folds = folded_triangles(&mesh.triangles, &plane);
    let folds_projected = folds.len();
    if (folds.len() as f64) <= MAX_FOLD_FRACTION * mesh.triangles.len() as f64 {
        // A few folds at grazing silhouettes: leave them out of the mapped mesh (they only
        // serve point location); their vertices keep their projected parameters as data.
        let mut near_fold = vec![false; plane.len()];
        leave_out_folds(&mut mesh.triangles, &folds, &mut near_fold);
        return Ok(PlanarMap {
            mesh,
            plane,
            method: MapMethod::Projection,
            folds_projected,
            near_fold,
            warp: None,
            folds_warped: 0,
        });
    }
    // Not a height field over any plane: the provably bijective map.
    let mut disk = mean_value_disk(patch)?;
    // Scale to the patch's size so grid spacings stay in the input's units.
    let length_3d: f64 = ring_length(patch.outer.iter().map(|&v| mesh.positions[v as usize]));
    let length_2d: f64 = ring_length(patch.outer.iter().map(|&v| disk[v as usize].extend(0.0)));
    let s = if length_2d > 0.0 {
        length_3d / length_2d
    } else {
        1.0
    };
    for p in &mut disk {
        *p *= s;
    }
    let left = folded_triangles(&patch.mesh.triangles, &disk);
    if !left.is_empty() {
        return Err(RemeshError::Parameterization(MapFailure::FoldsRemain {
            count: left.len(),
        }));
    }
    Ok(PlanarMap {
        near_fold: vec![false; disk.len()],
        mesh: patch.mesh.clone(),
        plane: disk,
        method: MapMethod::MeanValueDisk,
        folds_projected,
        warp: None,
        folds_warped: 0,
    })
}

/// Lattice triangles of the warp over a patch's data: ~1 per control point at the default
/// 5 % controls of a 40k-point scan. Measured on the Stanford scans: 1000 leaves chin at
/// 74.7 um, 2000 at 72.9; the warp costs ~10 ms either way.
const WARP_LATTICE_TRIANGLES: usize = 2000;
const WARP_ITERATIONS: usize = 5;

/// The warp `evened_out` builds for the projection of `data` (the patch before its holes
/// are filled: the warp reads only data triangles), so that it can be built beside the
/// filling and handed to `evened_out` as the one to reuse. `None` also where the data
/// alone fold more than the share of triangles a projection map may fold: `planar_map`
/// then falls back to the disk, which is not warped (should it not, `evened_out` builds
/// the warp itself, the same one).
pub(crate) fn projection_warp(data: &TriMesh, frame: &PlaneFrame) -> Option<PlaneWarp> {
    let plane: Vec<DVec2> = data.positions.iter().map(|&p| frame.project(p)).collect();
    let folds = folded_triangles(&data.triangles, &plane).len();
    if folds as f64 > MAX_FOLD_FRACTION * data.triangles.len() as f64 {
        return None;
    }
    PlaneWarp::build(
        &data.positions,
        &plane,
        &data.triangles,
        WARP_LATTICE_TRIANGLES,
        WARP_ITERATIONS,
    )
}

/// A projection map composed with a `PlaneWarp` that evens out its stretch (see
/// `warp`): the previous version's warp when it covers this version's points (the
/// parameters of the two versions then agree), else a new one. Maps of other kinds come
/// back unchanged. Triangles the warp folds join the projection's folds: left out of the
/// mapped mesh, their vertices marked.
pub fn evened_out(
    mut map: PlanarMap,
    patch: &FilledPatch,
    previous: Option<&PlaneWarp>,
) -> PlanarMap {
    if map.method != MapMethod::Projection {
        return map;
    }
    let real = &patch.mesh.triangles[..patch.real_triangles];
    let warp = match previous.filter(|w| w.covers(&map.plane)) {
        Some(w) => Some(w.clone()),
        None => PlaneWarp::build(
            &patch.mesh.positions,
            &map.plane,
            real,
            WARP_LATTICE_TRIANGLES,
            WARP_ITERATIONS,
        ),
    };
    let Some(warp) = warp else {
        return map;
    };
    map.plane
        .par_iter_mut()
        .with_min_len(4096)
        .for_each(|p| *p = warp.apply(*p));
    let folds = folded_triangles(&map.mesh.triangles, &map.plane);
    map.folds_warped = folds.len();
    leave_out_folds(&mut map.mesh.triangles, &folds, &mut map.near_fold);
    map.warp = Some(warp);
    map
}

/// Removes the triangles `folds` (indices, increasing) from `tris` and marks their
/// vertices in `near_fold`.
fn leave_out_folds(tris: &mut Vec<[u32; 3]>, folds: &[usize], near_fold: &mut [bool]) {
    if folds.is_empty() {
        return;
    }
    let mut drop = vec![false; tris.len()];
    for &f in folds {
        drop[f] = true;
        for v in tris[f] {
            near_fold[v as usize] = true;
        }
    }
    let mut k = 0;
    tris.retain(|_| {
        k += 1;
        !drop[k - 1]
    });
}

fn ring_length(points: impl Iterator<Item = DVec3>) -> f64 {
    let pts: Vec<DVec3> = points.collect();
    (0..pts.len())
        .map(|k| (pts[(k + 1) % pts.len()] - pts[k]).length())
        .sum()
}

/// Ear clipping of a simple counter-clockwise polygon; `None` when no ear is left (the
/// polygon is not simple in the plane).
fn ear_clip(poly: &[u32], plane: &[DVec2]) -> Option<Vec<[u32; 3]>> {
    let mut ring: Vec<u32> = poly.to_vec();
    let mut out = Vec::with_capacity(poly.len().saturating_sub(2));
    let at = |v: u32| plane[v as usize];
    let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    // The search resumes where the last ear was cut: ears cluster, which keeps the usual
    // cost quadratic.
    let mut from = 0;
    while ring.len() > 3 {
        let n = ring.len();
        let ear = (0..n).map(|d| (from + d) % n).find(|&k| {
            let (a, b, c) = (ring[(k + n - 1) % n], ring[k], ring[(k + 1) % n]);
            let (pa, pb, pc) = (at(a), at(b), at(c));
            if cross(pa, pb, pc) <= 0.0 {
                return false;
            }
            ring.iter().all(|&v| {
                if v == a || v == b || v == c {
                    return true;
                }
                let p = at(v);
                !(cross(pa, pb, p) >= 0.0 && cross(pb, pc, p) >= 0.0 && cross(pc, pa, p) >= 0.0)
            })
        })?;
        let (a, b, c) = (ring[(ear + n - 1) % n], ring[ear], ring[(ear + 1) % n]);
        out.push([a, b, c]);
        ring.remove(ear);
        from = ear.saturating_sub(1);
    }
    if ring.len() == 3 {
        if cross(at(ring[0]), at(ring[1]), at(ring[2])) <= 0.0 {
            return None;
        }
        out.push([ring[0], ring[1], ring[2]]);
    }
    Some(out)
}
