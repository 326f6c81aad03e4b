//! Corners of the data's rim kept as corners of the limit surface.
//!
//! Why: Loop's boundary rule makes the surface's rim the cubic B-spline of the control
//! mesh's boundary polygon, smooth at every boundary control except a corner (a boundary
//! vertex of a single face, which the limit surface interpolates). A rim that turns
//! sharply (the corners of a rectangular patch or cut-out) is cut off by such a spline,
//! and fitting the rim to the data then pushes the controls near the corner outward, so
//! the rim overshoots along the sides. Measured on a 23 x 23 height patch with 26
//! controls: the held rim points stood 0.22 RMS from the boundary curve (0.97 at the
//! corners) while the interior fitted to 0.014. Hoppe et al. (1994) tag such vertices as
//! corners; here a control vertex is a corner when the data's rim turns sharply at the
//! data vertex it was simplified from and the control polygon turns sharply there too
//! (a round rim seen through few controls turns sharply in the polygon only, and a noisy
//! rim vertex in the data only).

use super::layout::{edge_key, Net, MAX_FACES, MIN_FLIP_QUALITY};
use crate::mesh::topology::Topology;
use crate::mesh::{triangle_area_normal, triangle_quality};
use crate::TriMesh;
use glam::DVec3;

/// Boundary vertices of `control` to make corners: each one's interior angle (the sum of
/// its face angles) is below `180 - turn_deg` degrees in the control mesh and at the data
/// vertex of `data` it was simplified from (`control_of`: per data vertex, its control
/// vertex or a value out of range when it was removed).
pub(super) fn rim_corners(
    data: &TriMesh,
    data_topo: &Topology,
    control: &TriMesh,
    control_of: &[u32],
    turn_deg: f64,
) -> Vec<u32> {
    let Ok(control_topo) = Topology::from_mesh(control) else {
        return Vec::new();
    };
    let max_angle = (180.0 - turn_deg).to_radians();
    let sharp = |mesh: &TriMesh, topo: &Topology, v: u32| {
        topo.is_boundary(v) && interior_angle(&mesh.positions, topo.ring(v), v) < max_angle
    };
    let mut corners: Vec<u32> = control_of
        .iter()
        .enumerate()
        .filter(|&(_, &c)| (c as usize) < control.positions.len())
        .filter(|&(d, &c)| sharp(data, data_topo, d as u32) && sharp(control, &control_topo, c))
        .map(|(_, &c)| c)
        .collect();
    corners.sort_unstable();
    corners.dedup();
    corners
}

/// The angle a boundary vertex's faces span at it (its ring runs from one boundary
/// neighbour to the other).
fn interior_angle(positions: &[DVec3], ring: &[u32], v: u32) -> f64 {
    let p = positions[v as usize];
    ring.windows(2)
        .map(|w| (positions[w[0] as usize] - p).angle_between(positions[w[1] as usize] - p))
        .sum()
}

/// A flip of the interior edge (v, b) between faces f = (v, b, c) and g = (b, v, d),
/// taking a face from v, with the worse quality of the two faces it makes.
struct CornerFlip {
    f: u32,
    g: u32,
    corners: [u32; 4],
    quality: f64,
}

impl Net<'_> {
    /// Gives every boundary vertex of a single face that is not in `wanted` a second face,
    /// by splitting the edge opposite it at its midpoint. Returns the splits made.
    ///
    /// Why: such a vertex is a Loop corner, whose control point the limit surface
    /// interpolates; the simplification keeps one wherever the data's rim has a vertex of
    /// a single face (a sliver at a scan's rim), and with little data on its one face the
    /// fitted control, and the surface with it, stood 4 mm off bun_zipper's data.
    pub(super) fn open_stray_corners(&mut self, wanted: &[u32]) -> usize {
        let mut opened = 0;
        for v in 0..self.pos.len() as u32 {
            if !self.boundary[v as usize]
                || self.vfaces[v as usize].len() != 1
                || wanted.contains(&v)
            {
                continue;
            }
            let t = self.faces[self.vfaces[v as usize][0] as usize];
            let Some(k) = t.iter().position(|&x| x == v) else {
                continue;
            };
            let (a, b) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let mid = 0.5 * (self.pos[a as usize] + self.pos[b as usize]);
            if self.split_edge(a, b, mid) {
                opened += 1;
            }
        }
        opened
    }

    /// Marks the boundary vertices that already have a single face as corners to keep
    /// (a refined or previous control mesh whose corners were made by `make_corners`).
    pub(super) fn keep_corners(&mut self) {
        for v in 0..self.corner.len() {
            self.corner[v] = self.boundary[v] && self.vfaces[v].len() == 1;
        }
    }

    /// Makes each of `wanted` (boundary vertices) a corner by flipping interior edges at
    /// it, best new faces first, until it has one face; a vertex whose flips the guards
    /// refuse stays smooth. Returns the corners made (or found).
    pub(super) fn make_corners(&mut self, wanted: &[u32], cos_fold: f64) -> usize {
        let mut made = 0;
        for &v in wanted {
            if !self.boundary.get(v as usize).copied().unwrap_or(false) {
                continue;
            }
            while self.vfaces[v as usize].len() > 1 {
                let Some(best) = self
                    .corner_flips(v, cos_fold)
                    .max_by(|x, y| x.quality.total_cmp(&y.quality))
                else {
                    break;
                };
                self.flip(best.f, best.g, best.corners);
            }
            if self.vfaces[v as usize].len() == 1 {
                self.corner[v as usize] = true;
                made += 1;
            }
        }
        made
    }

    /// The flips that take a face from `v` and pass the guards of an ordinary flip
    /// (no crease crossed, no corner given a face, no fold cut, no bad face made).
    fn corner_flips(&self, v: u32, cos_fold: f64) -> impl Iterator<Item = CornerFlip> + '_ {
        self.vfaces[v as usize].iter().filter_map(move |&f| {
            let t = self.faces[f as usize];
            let k = t.iter().position(|&x| x == v)?;
            let (b, c) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let g = self.vfaces[v as usize]
                .iter()
                .copied()
                .find(|&g| g != f && self.faces[g as usize].contains(&b))?;
            let d = *self.faces[g as usize].iter().find(|&&x| x != v && x != b)?;
            let min_b = if self.boundary[b as usize] { 3 } else { 4 };
            let refused = c == d
                || self.corner[b as usize]
                || self.corner[c as usize]
                || self.corner[d as usize]
                || self.creases.contains(&edge_key(v, b))
                || self.vfaces[b as usize].len() < min_b
                || [c, d]
                    .iter()
                    .any(|&x| self.vfaces[x as usize].len() >= MAX_FACES)
                || self.vfaces[c as usize]
                    .iter()
                    .any(|&h| self.faces[h as usize].contains(&d));
            if refused {
                return None;
            }
            let p = |x: u32| self.pos[x as usize];
            let (n0, n1) = (
                triangle_area_normal([p(v), p(b), p(c)]),
                triangle_area_normal([p(b), p(v), p(d)]),
            );
            if n0.dot(n1) < cos_fold * n0.length() * n1.length() {
                return None;
            }
            let up = n0 + n1;
            let new = [[p(v), p(d), p(c)], [p(d), p(b), p(c)]];
            let upright = new.iter().all(|&tri| {
                let n = triangle_area_normal(tri);
                n.dot(up) > 0.5 * n.length() * up.length()
            });
            let q = triangle_quality(new[0]).min(triangle_quality(new[1]));
            (upright && q >= MIN_FLIP_QUALITY).then_some(CornerFlip {
                f,
                g,
                corners: [v, b, c, d],
                quality: q,
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::object::layout::tests::landed_on_own_faces;

    /// A flat 3 x 3 grid on [0, 2]^2, each square split by its rising diagonal: the
    /// corners (0, 0) and (2, 2) have two faces, (2, 0) and (0, 2) one. Vertex j * 3 + i
    /// is at (i, j).
    fn grid() -> TriMesh {
        let positions = (0..9)
            .map(|k| DVec3::new((k % 3) as f64, (k / 3) as f64, 0.0))
            .collect();
        let at = |i: u32, j: u32| j * 3 + i;
        let mut triangles = Vec::new();
        for j in 0..2 {
            for i in 0..2 {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        TriMesh::new(positions, triangles)
    }

    #[test]
    fn the_four_right_angles_of_a_square_rim_are_corners() {
        let mesh = grid();
        let topo = Topology::from_mesh(&mesh).expect("a manifold grid");
        let identity: Vec<u32> = (0..9).collect();
        assert_eq!(
            rim_corners(&mesh, &topo, &mesh, &identity, 75.0),
            vec![0, 2, 6, 8]
        );
        // Removed data vertices (out of range) are skipped.
        let removed = vec![u32::MAX; 9];
        assert!(rim_corners(&mesh, &topo, &mesh, &removed, 75.0).is_empty());
    }

    #[test]
    fn a_vertex_of_one_face_not_wanted_as_a_corner_gets_a_second() {
        let mesh = grid();
        let land = landed_on_own_faces(&mesh);
        let Some(mut net) = Net::new(&mesh, mesh.clone(), &land, &[]) else {
            panic!("the grid is a manifold");
        };
        // (2, 0) and (0, 2) have one face each; (0, 2) is wanted as a corner.
        assert_eq!(net.open_stray_corners(&[6]), 1);
        assert_eq!(net.vfaces[2].len(), 2);
        assert_eq!(net.vfaces[6].len(), 1);
        assert_eq!(net.pos.len(), 10);
        assert_eq!(net.pos[9], DVec3::new(1.5, 0.5, 0.0));
    }

    #[test]
    fn a_corner_is_left_with_one_face_and_keeps_it_through_splits() {
        let mesh = grid();
        let land = landed_on_own_faces(&mesh);
        let Some(mut net) = Net::new(&mesh, mesh.clone(), &land, &[]) else {
            panic!("the grid is a manifold");
        };
        let made = net.make_corners(&[0, 8], 0.9);
        assert_eq!(made, 2);
        let (faces_of_0, faces_of_8) = (net.vfaces[0].len(), net.vfaces[8].len());
        assert_eq!((faces_of_0, faces_of_8), (1, 1));
        // The edge opposite corner 0 now runs (1, 0)-(0, 1): splitting it would give the
        // corner a second face, so it is refused; an edge at the corner splits.
        assert!(net.has_edge(1, 3));
        assert!(!net.split_edge(1, 3, DVec3::new(0.5, 0.5, 0.0)));
        assert!(net.split_edge(0, 1, DVec3::new(0.5, 0.0, 0.0)));
        assert_eq!(net.vfaces[0].len(), 1);
        let (control, landing, _) = net.finish();
        // Flat data: every landing reproduces its point exactly after the flips and split.
        for (p, l) in landing.iter().enumerate() {
            let t = control.triangles[l.face as usize].map(|v| control.positions[v as usize]);
            let x = t[0] * l.u + t[1] * l.v + t[2] * (1.0 - l.u - l.v);
            assert!(x.distance(mesh.positions[p]) < 1e-12, "point {p} at {x}");
        }
    }
}
