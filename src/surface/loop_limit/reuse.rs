//! Patches of a previous surface taken over by a new one over a changed control mesh.
//!
//! Why: a whole-object fit refines its control mesh locally and builds the limit surface
//! of each refined mesh; most of an irregular patch's cost is the quadtree of child nets
//! its evaluations memoise, and faces away from the splits keep their 1-ring, so their
//! patches (memo included) are the same and need not be built again.

use super::net::Net;
use super::{FacePatch, LoopLimitSurface};
use std::collections::HashMap;

/// The irregular patches of a surface, by their face's corners in order.
pub(super) struct Reusable<'a> {
    surface: &'a LoopLimitSurface,
    by_corners: HashMap<[u32; 3], usize>,
}

impl<'a> Reusable<'a> {
    pub(super) fn new(surface: &'a LoopLimitSurface) -> Self {
        let by_corners = surface
            .topo
            .triangles
            .iter()
            .enumerate()
            .filter(|&(f, _)| matches!(surface.patches[f], FacePatch::Irregular(_)))
            .map(|(f, t)| (*t, f))
            .collect();
        Self {
            surface,
            by_corners,
        }
    }

    /// The previous patch of the face with `corners`, if it was irregular and was built
    /// from the same root net: the same support (original control indices) and the same
    /// 1-ring (triangles, boundary and crease flags, faces around each support vertex).
    /// A root net's weights are the identity over its support, so nothing else differs.
    pub(super) fn patch(&self, corners: [u32; 3], support: &[u32], net: &Net) -> Option<FacePatch> {
        let f = *self.by_corners.get(&corners)?;
        let FacePatch::Irregular(ip) = self.surface.patches.get(f)? else {
            return None;
        };
        let old = &ip.root.net;
        let same = ip.support == support
            && old.nsup == net.nsup
            && old.tris == net.tris
            && old.bnd == net.bnd
            && old.crease == net.crease
            && old.faces_total == net.faces_total;
        same.then(|| FacePatch::Irregular(ip.clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::{SurfaceParam, TriSurface};
    use glam::DVec3;
    use std::sync::Arc;

    /// The icosahedron with each face split 1-to-4 (80 faces, valence 5 at the 12 old
    /// vertices, 6 elsewhere), on the unit sphere.
    fn sphere() -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let (corners, faces) = crate::testdata::icosahedron();
        let mut positions: Vec<DVec3> = corners.into_iter().map(DVec3::normalize).collect();
        let mut mid = HashMap::new();
        let mut split = Vec::with_capacity(4 * faces.len());
        for t in &faces {
            let m = [0, 1, 2].map(|k| {
                let key = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                *mid.entry(key).or_insert_with(|| {
                    let p = positions[key.0 as usize] + positions[key.1 as usize];
                    positions.push(p.normalize());
                    positions.len() as u32 - 1
                })
            });
            split.extend([
                [t[0], m[0], m[2]],
                [t[1], m[1], m[0]],
                [t[2], m[2], m[1]],
                m,
            ]);
        }
        (positions, split)
    }

    /// `sphere` with edge (a, b) split at its midpoint: the two faces on it changed in
    /// place or added, every other face kept as it was.
    fn split_sphere(a: u32, b: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let (mut positions, mut faces) = sphere();
        let m = positions.len() as u32;
        positions.push(0.5 * (positions[a as usize] + positions[b as usize]));
        let on_edge: Vec<(usize, usize)> = faces
            .iter()
            .enumerate()
            .filter_map(|(f, t)| {
                let k = (0..3).find(|&k| {
                    let (x, y) = (t[k], t[(k + 1) % 3]);
                    (x, y) == (a, b) || (x, y) == (b, a)
                })?;
                Some((f, k))
            })
            .collect();
        for (f, k) in on_edge {
            let t = faces[f];
            let (x, y, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            faces[f] = [x, m, c];
            faces.push([m, y, c]);
        }
        (positions, faces)
    }

    #[test]
    fn a_refined_mesh_shares_the_unchanged_patches_and_evaluates_as_built_afresh() {
        let (positions, faces) = sphere();
        let first = LoopLimitSurface::new(positions.len(), &faces).expect("a closed mesh");
        // Evaluations fill the first surface's memo, which the second then carries.
        let probes = [(0.3, 0.3), (0.01, 0.02), (0.9, 0.05), (1e-6, 1e-6)];
        let evaluate_all = |s: &LoopLimitSurface, controls: &[DVec3]| -> Vec<DVec3> {
            (0..s.domain_face_count() as u32)
                .flat_map(|face| probes.map(|(u, v)| SurfaceParam { face, u, v }))
                .flat_map(|p| {
                    let d = s.evaluate(controls, p);
                    [d.position, d.du, d.dv]
                })
                .collect()
        };
        evaluate_all(&first, &positions);
        let (a, b) = (faces[0][0], faces[0][1]);
        let (refined, refined_faces) = split_sphere(a, b);
        let fresh = LoopLimitSurface::new(refined.len(), &refined_faces).expect("a closed mesh");
        let reused =
            LoopLimitSurface::with_creases_reusing(refined.len(), &refined_faces, &[], &first)
                .expect("a closed mesh");
        let shared = reused
            .patches
            .iter()
            .filter(|p| matches!(p, FacePatch::Irregular(ip) if Arc::strong_count(ip) > 1))
            .count();
        // Faces near the split changed their 1-ring; the irregular ones on the far side
        // of the sphere were taken over.
        assert!(shared > 0, "no patch was reused");
        assert!(shared < refined_faces.len(), "changed patches were reused");
        assert_eq!(
            evaluate_all(&fresh, &refined),
            evaluate_all(&reused, &refined),
            "a reused patch evaluates differently"
        );
    }
}
