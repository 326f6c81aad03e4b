//! One quadtree of child nets per 1-ring shape, shared by the faces of that shape and
//! handed on to the surface of a refined control mesh.
//!
//! Why: most of an irregular patch's cost is the quadtree of child nets its evaluations
//! memoise. A tree is a function of its root net alone, and a root net is the identity
//! over the face's 1-ring listed in a canonical order (`LoopLimitSurface::face_net`), so
//! it is fixed by the 1-ring's shape: triangles, boundary and crease flags and the faces
//! around each vertex. A control mesh from simplification has few shapes (the valences of
//! a face's corners and their neighbours), so faces share trees, and a refined control
//! mesh finds most of its shapes already built, with their memo, in the previous surface.

use super::net::Net;
use super::{FacePatch, LoopLimitSurface, Tree};
use std::collections::HashMap;
use std::sync::Arc;

/// What identifies a root net: everything in it but its weights, which are the identity.
#[derive(Clone, PartialEq, Eq, Hash)]
struct Shape {
    tris: Vec<[u32; 3]>,
    bnd: Vec<[bool; 3]>,
    crease: Vec<[bool; 3]>,
    faces_total: Vec<u32>,
}

impl Shape {
    fn of(net: &Net) -> Self {
        Self {
            tris: net.tris.clone(),
            bnd: net.bnd.clone(),
            crease: net.crease.clone(),
            faces_total: net.faces_total.clone(),
        }
    }
}

/// The quadtrees built so far, by the shape of their root net.
#[derive(Default)]
pub(super) struct Trees {
    by_shape: HashMap<Shape, Arc<Tree>>,
}

impl Trees {
    /// The trees of a surface's irregular faces.
    pub(super) fn of(surface: &LoopLimitSurface) -> Self {
        let mut trees = Self::default();
        for patch in &surface.patches {
            if let FacePatch::Irregular(ip) = patch {
                trees
                    .by_shape
                    .entry(Shape::of(&ip.tree.root.net))
                    .or_insert_with(|| ip.tree.clone());
            }
        }
        trees
    }

    /// The tree whose root is `net`: one already built for its shape, else a new one.
    pub(super) fn tree(&mut self, net: Net) -> Arc<Tree> {
        self.by_shape
            .entry(Shape::of(&net))
            .or_insert_with(|| Arc::new(Tree::new(net)))
            .clone()
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
    fn faces_of_one_shape_share_a_tree_which_a_refined_mesh_takes_over_and_evaluates_as_built_afresh(
    ) {
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
        let roots = |s: &LoopLimitSurface| -> Vec<*const Tree> {
            s.patches
                .iter()
                .filter_map(|p| match p {
                    FacePatch::Irregular(ip) => Some(Arc::as_ptr(&ip.tree)),
                    _ => None,
                })
                .collect()
        };
        let before = roots(&first);
        let after = roots(&reused);
        let taken_over = after.iter().filter(|r| before.contains(r)).count();
        // Faces of the split changed their 1-ring's shape (valences 4 and 7 appear); the
        // irregular faces of the old shapes took over the first surface's trees.
        assert!(taken_over > 0, "no tree was taken over");
        assert!(taken_over < after.len(), "new shapes took over old trees");
        // The icosahedron's irregular faces are the 60 corner children of its faces,
        // each with its valence-5 corner first (`sphere`): one shape, one tree.
        let mut distinct = before.clone();
        distinct.sort();
        distinct.dedup();
        assert_eq!((before.len(), distinct.len()), (60, 1));
        assert_eq!(
            evaluate_all(&fresh, &refined),
            evaluate_all(&reused, &refined),
            "a reused patch evaluates differently"
        );
    }

    #[test]
    fn faces_sharing_a_tree_evaluate_over_their_own_controls() {
        let (positions, faces) = sphere();
        let surface = LoopLimitSurface::new(positions.len(), &faces).expect("a closed mesh");
        let shared: Vec<u32> = (0..faces.len() as u32)
            .filter(|&f| matches!(surface.patches[f as usize], FacePatch::Irregular(_)))
            .collect();
        let evaluate = surface.evaluator(&positions);
        // The same leaf of the shared tree, face after face: the evaluator's memo of the
        // last leaf must not hand one face's surface to the next.
        for &face in &shared {
            let p = SurfaceParam {
                face,
                u: 0.1,
                v: 0.05,
            };
            let cached = evaluate(p);
            let direct = surface.evaluate(&positions, p);
            assert!(
                cached.position.distance(direct.position) < 1e-12,
                "face {face}: {:?} vs {:?}",
                cached.position,
                direct.position
            );
        }
    }
}
