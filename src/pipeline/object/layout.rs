//! The layout of a simplified control mesh, improved at the same vertex count before it is
//! fitted: edge flips toward regular valences (6 inside, 4 on the boundary) and tangential
//! relaxation of the interior control vertices, each moved vertex put back on the data
//! (the isotropic-remeshing steps of Botsch & Kobbelt 2004 without splits and collapses).
//!
//! Why: a Loop limit surface is a single box-spline patch over faces whose corners are all
//! regular and degrades around extraordinary vertices and long thin faces; quadric
//! decimation places vertices well for a flat-faced approximation but leaves many
//! irregular vertices and uneven faces, and on a torus a structured mesh with as many
//! controls fits six times closer. Every data point stays on a control face (its landing)
//! through the changes: the points of changed faces are re-projected onto the nearby faces,
//! as during simplification, so a point never jumps to the far side of a thin part.
//!
//! Crease edges are kept as they are: never flipped (a flip would cut across the sharp
//! edge), their vertices never relaxed (a tangential slide on the data would pull the
//! vertex off the edge), and a split crease edge leaves two crease edges.

use crate::mesh::distance::{closest_on_triangle, project_onto_triangle};
use crate::mesh::topology::Topology;
use crate::mesh::{triangle_area_normal, triangle_quality};
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashSet;

/// How much of the layout work is done.
#[derive(Clone, Debug)]
pub struct LayoutOptions {
    /// Rounds of (flips, relaxation); 0 keeps the simplification's layout.
    pub rounds: usize,
    /// Sweeps over all edges per round (a round stops early when a sweep flips nothing).
    pub flip_sweeps: usize,
    /// Relaxation steps per round.
    pub relax_steps: usize,
    /// Share of the way to the neighbours' centroid a relaxation step moves a vertex.
    pub relax_step: f64,
    /// Edges are flipped only between faces whose normals differ by less than this: a
    /// flip across a fold would cut it off.
    pub max_fold_deg: f64,
}

impl Default for LayoutOptions {
    fn default() -> Self {
        Self {
            rounds: 3,
            flip_sweeps: 4,
            // Relaxation measured no better than flips alone (bun_zipper, fertility,
            // decimated-max, camelhead, a torus knot): off unless asked for.
            relax_steps: 0,
            relax_step: 0.5,
            max_fold_deg: 25.0,
        }
    }
}

/// What the layout changed.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct LayoutReport {
    /// Control vertices whose valence is not the regular one, before ...
    pub irregular_before: usize,
    /// ... and after.
    pub irregular_after: usize,
    /// Edge flips made.
    pub flips: usize,
    /// Relaxation steps made.
    pub relax_steps: usize,
    /// Corners of the data's rim made Loop corners of the control mesh.
    pub corners: usize,
    /// Other boundary vertices of a single face (Loop corners the data does not ask for)
    /// given a second face by a split, each adding a control.
    pub stray_corners_opened: usize,
    /// The simplification ran without its triangle-quality guard, which cost the control
    /// mesh too much of its shape or its budget (`simplification`).
    pub quality_guard_dropped: bool,
}

/// Faces of a quality below this are never created by a flip.
pub(super) const MIN_FLIP_QUALITY: f64 = 0.05;
/// Faces around a vertex at most after a flip (the simplification's limit).
pub(super) const MAX_FACES: usize = 12;
/// A relaxation step is refused where it turns a face normal by more than this.
const MAX_RELAX_TURN_DEG: f64 = 30.0;
/// Passes of re-landing after a relaxation step (a point moves at most one face ring per
/// pass).
const RELAND_PASSES: usize = 2;

/// Improves the layout of `control` (simplified from `data`, each data vertex landed at
/// `landing` on it) and carries the landings along; the boundary vertices `corners` are
/// made Loop corners first where flips allow (see `corners`).
pub(super) fn improve_layout(
    data: &TriMesh,
    control: TriMesh,
    landing: Vec<SurfaceParam>,
    creases: &[[u32; 2]],
    corners: &[u32],
    opts: &LayoutOptions,
) -> (TriMesh, Vec<SurfaceParam>, Vec<[u32; 2]>, LayoutReport) {
    let Some(mut net) = Net::new(data, control.clone(), &landing, creases) else {
        return (control, landing, creases.to_vec(), LayoutReport::default());
    };
    // Before the flips: opened after them, bun_zipper's rim sliver at 2 % controls left a
    // boundary control 4 mm off the data (1.1 mm when opened first).
    let stray_corners_opened = net.open_stray_corners(corners);
    let corners = net.make_corners(corners, opts.max_fold_deg.to_radians().cos());
    let report = LayoutReport {
        corners,
        stray_corners_opened,
        ..net.tidy(opts)
    };
    let (mesh, landing, creases) = net.finish();
    (mesh, landing, creases, report)
}

/// An undirected edge as a key.
pub(super) fn edge_key(a: u32, b: u32) -> [u32; 2] {
    [a.min(b), a.max(b)]
}

/// The control mesh being changed, with face lists per vertex and the landings.
pub(super) struct Net<'a> {
    data: &'a TriMesh,
    /// Data triangles per data vertex (for putting moved controls back on the data).
    data_faces: Vec<Vec<u32>>,
    pub(super) pos: Vec<DVec3>,
    pub(super) faces: Vec<[u32; 3]>,
    pub(super) vfaces: Vec<Vec<u32>>,
    pub(super) boundary: Vec<bool>,
    /// Per data point: its face and barycentric weights of the face's corners.
    land: Vec<(u32, [f64; 3])>,
    face_points: Vec<Vec<u32>>,
    /// Crease edges (sorted pairs) and the vertices on them.
    pub(super) creases: HashSet<[u32; 2]>,
    on_crease: Vec<bool>,
    /// Loop corners kept: boundary vertices of a single face, which the limit surface
    /// interpolates (see `corners`); no flip or split gives them a second face. None
    /// until `make_corners` or `keep_corners` marks them.
    pub(super) corner: Vec<bool>,
}

impl<'a> Net<'a> {
    /// The net of `control` with the data's landings on it, or `None` if the control mesh
    /// is not a manifold or a landing names no face.
    pub(super) fn new(
        data: &'a TriMesh,
        control: TriMesh,
        landing: &[SurfaceParam],
        crease_edges: &[[u32; 2]],
    ) -> Option<Self> {
        let topo = Topology::from_mesh(&control).ok()?;
        let mut on_crease = vec![false; control.positions.len()];
        let mut creases = HashSet::with_capacity(crease_edges.len());
        for &[a, b] in crease_edges {
            *on_crease.get_mut(a as usize)? = true;
            *on_crease.get_mut(b as usize)? = true;
            creases.insert(edge_key(a, b));
        }
        let nf = control.triangles.len();
        if landing.len() != data.positions.len() || landing.iter().any(|l| l.face as usize >= nf) {
            return None;
        }
        let mut vfaces = vec![Vec::new(); control.positions.len()];
        for (f, t) in control.triangles.iter().enumerate() {
            for &v in t {
                vfaces[v as usize].push(f as u32);
            }
        }
        let mut data_faces = vec![Vec::new(); data.positions.len()];
        for (f, t) in data.triangles.iter().enumerate() {
            for &v in t {
                data_faces.get_mut(v as usize)?.push(f as u32);
            }
        }
        let mut face_points = vec![Vec::new(); nf];
        let land = landing
            .iter()
            .enumerate()
            .map(|(p, l)| {
                face_points[l.face as usize].push(p as u32);
                (l.face, [l.u, l.v, 1.0 - l.u - l.v])
            })
            .collect();
        Some(Self {
            corner: vec![false; vfaces.len()],
            data,
            data_faces,
            pos: control.positions,
            faces: control.triangles,
            vfaces,
            boundary: topo.boundary,
            land,
            face_points,
            creases,
            on_crease,
        })
    }

    /// Rounds of flips and relaxation (see [`LayoutOptions`]).
    pub(super) fn tidy(&mut self, opts: &LayoutOptions) -> LayoutReport {
        let mut report = LayoutReport {
            irregular_before: self.irregular(),
            ..Default::default()
        };
        for _ in 0..opts.rounds {
            for _ in 0..opts.flip_sweeps {
                let flips = self.flip_sweep(opts.max_fold_deg.to_radians().cos());
                report.flips += flips;
                if flips == 0 {
                    break;
                }
            }
            for _ in 0..opts.relax_steps {
                self.relax(opts.relax_step);
                self.reland();
                report.relax_steps += 1;
            }
        }
        report.irregular_after = self.irregular();
        report
    }

    /// Splits the edge (a, b) at a new vertex placed at `at`: each face (x, y, c) on it
    /// (x, y being a, b in the face's order) becomes (x, m, c) and (m, y, c), and the
    /// face's points are re-landed on the two halves. `false` if there is no such edge or
    /// a corner is opposite it.
    pub(super) fn split_edge(&mut self, a: u32, b: u32, at: DVec3) -> bool {
        let on_edge: Vec<u32> = self.vfaces[a as usize]
            .iter()
            .copied()
            .filter(|&f| self.faces[f as usize].contains(&b))
            .collect();
        if on_edge.is_empty() || on_edge.len() > 2 {
            return false;
        }
        // Splitting the edge opposite a corner would give the corner a second face.
        let opposite_corner = on_edge.iter().any(|&f| {
            self.faces[f as usize]
                .iter()
                .any(|&c| c != a && c != b && self.corner[c as usize])
        });
        if opposite_corner {
            return false;
        }
        let m = self.pos.len() as u32;
        self.pos.push(at);
        self.corner.push(false);
        self.vfaces.push(Vec::with_capacity(6));
        self.boundary.push(on_edge.len() == 1);
        let crease = self.creases.remove(&edge_key(a, b));
        self.on_crease.push(crease);
        if crease {
            self.creases.insert(edge_key(a, m));
            self.creases.insert(edge_key(m, b));
        }
        for f in on_edge {
            let t = self.faces[f as usize];
            let Some(k) = (0..3).find(|&k| {
                let (x, y) = (t[k], t[(k + 1) % 3]);
                (x, y) == (a, b) || (x, y) == (b, a)
            }) else {
                continue;
            };
            let (x, y, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let g = self.faces.len() as u32;
            self.faces[f as usize] = [x, m, c];
            self.faces.push([m, y, c]);
            self.face_points.push(Vec::new());
            for h in self.vfaces[y as usize].iter_mut() {
                if *h == f {
                    *h = g;
                }
            }
            self.vfaces[c as usize].push(g);
            self.vfaces[m as usize].extend([f, g]);
            let points = std::mem::take(&mut self.face_points[f as usize]);
            for p in points {
                let (face, bary) = self.nearest_face(self.data.positions[p as usize], &[f, g]);
                self.land[p as usize] = (face, bary);
                self.face_points[face as usize].push(p);
            }
        }
        true
    }

    /// Whether the edge (a, b) is in the mesh.
    pub(super) fn has_edge(&self, a: u32, b: u32) -> bool {
        self.vfaces[a as usize]
            .iter()
            .any(|&f| self.faces[f as usize].contains(&b))
    }

    /// Neighbours of `v` (faces around it, plus one on the boundary).
    fn valence(&self, v: u32) -> usize {
        self.vfaces[v as usize].len() + usize::from(self.boundary[v as usize])
    }

    fn regular_valence(&self, v: u32) -> usize {
        if self.boundary[v as usize] {
            4
        } else {
            6
        }
    }

    fn irregular(&self) -> usize {
        (0..self.pos.len() as u32)
            .filter(|&v| self.valence(v) != self.regular_valence(v))
            .count()
    }

    fn corners(&self, f: u32) -> [DVec3; 3] {
        self.faces[f as usize].map(|v| self.pos[v as usize])
    }

    /// One sweep over the interior edges, flipping each that lowers the squared valence
    /// deviation of its four vertices and passes the geometric guards.
    fn flip_sweep(&mut self, cos_fold: f64) -> usize {
        let mut flips = 0;
        for f in 0..self.faces.len() as u32 {
            for k in 0..3 {
                let t = self.faces[f as usize];
                let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                if a > b {
                    continue;
                }
                let Some(g) = self.vfaces[a as usize]
                    .iter()
                    .copied()
                    .find(|&g| g != f && self.faces[g as usize].contains(&b))
                else {
                    continue;
                };
                let Some(&d) = self.faces[g as usize].iter().find(|&&x| x != a && x != b) else {
                    continue;
                };
                if self.flip_wanted(a, b, c, d, cos_fold) {
                    self.flip(f, g, [a, b, c, d]);
                    flips += 1;
                }
            }
        }
        flips
    }

    fn flip_wanted(&self, a: u32, b: u32, c: u32, d: u32, cos_fold: f64) -> bool {
        // No interior edge between two rim vertices, as in the simplification: it bridges
        // the data across the rim (measured on chin_tri at 10 % controls: such edges made
        // long faces over gaps of the ragged rim, whose patches stood 4 mm off the data).
        if c == d
            || self.corner[c as usize]
            || self.corner[d as usize]
            || (self.boundary[c as usize] && self.boundary[d as usize])
            || self.creases.contains(&edge_key(a, b))
            || self.vfaces[c as usize]
                .iter()
                .any(|&h| self.faces[h as usize].contains(&d))
        {
            return false;
        }
        let deviation = |v: u32, change: isize| {
            let val = self.valence(v) as isize + change;
            (val - self.regular_valence(v) as isize).pow(2)
        };
        let before: isize = [a, b, c, d].iter().map(|&v| deviation(v, 0)).sum();
        let after = deviation(a, -1) + deviation(b, -1) + deviation(c, 1) + deviation(d, 1);
        if after >= before {
            return false;
        }
        // Faces left around each vertex: a boundary vertex keeps two (one would make it a
        // fixed Loop corner), an interior one three.
        let faces_ok = [a, b].iter().all(|&v| {
            let min = if self.boundary[v as usize] { 3 } else { 4 };
            self.vfaces[v as usize].len() >= min
        }) && [c, d]
            .iter()
            .all(|&v| self.vfaces[v as usize].len() < MAX_FACES);
        if !faces_ok {
            return false;
        }
        let p = |v: u32| self.pos[v as usize];
        let (n0, n1) = (
            triangle_area_normal([p(a), p(b), p(c)]),
            triangle_area_normal([p(b), p(a), p(d)]),
        );
        if n0.dot(n1) < cos_fold * n0.length() * n1.length() {
            return false;
        }
        let up = n0 + n1;
        [[p(a), p(d), p(c)], [p(d), p(b), p(c)]].iter().all(|&tri| {
            let n = triangle_area_normal(tri);
            n.dot(up) > 0.5 * n.length() * up.length() && triangle_quality(tri) >= MIN_FLIP_QUALITY
        })
    }

    /// Faces f = (a, b, c) and g = (b, a, d) become (a, d, c) and (d, b, c).
    pub(super) fn flip(&mut self, f: u32, g: u32, [a, b, c, d]: [u32; 4]) {
        self.faces[f as usize] = [a, d, c];
        self.faces[g as usize] = [d, b, c];
        self.vfaces[a as usize].retain(|&h| h != g);
        self.vfaces[b as usize].retain(|&h| h != f);
        self.vfaces[c as usize].push(g);
        self.vfaces[d as usize].push(f);
        let mut points = std::mem::take(&mut self.face_points[f as usize]);
        points.append(&mut self.face_points[g as usize]);
        for p in points {
            let (face, bary) = self.nearest_face(self.data.positions[p as usize], &[f, g]);
            self.land[p as usize] = (face, bary);
            self.face_points[face as usize].push(p);
        }
    }

    /// The nearest of `faces` to `q` and the barycentric weights of the closest point.
    fn nearest_face(&self, q: DVec3, faces: &[u32]) -> (u32, [f64; 3]) {
        let mut best = (f64::INFINITY, faces[0], [1.0, 0.0, 0.0]);
        for &f in faces {
            let (d2, bary) = project_onto_triangle(q, self.corners(f));
            if d2 < best.0 {
                best = (d2, f, bary);
            }
        }
        (best.1, best.2)
    }

    /// One Jacobi step: every interior vertex moves `step` of the way toward the
    /// area-weighted centroid of its faces' centroids, within its tangent plane, and is put
    /// back on the data nearby. Boundary vertices stay: they hold the holes' shapes.
    fn relax(&mut self, step: f64) {
        let cos_turn = MAX_RELAX_TURN_DEG.to_radians().cos();
        let moved: Vec<DVec3> = (0..self.pos.len() as u32)
            .into_par_iter()
            .map(|v| {
                self.relaxed(v, step, cos_turn)
                    .unwrap_or(self.pos[v as usize])
            })
            .collect();
        self.pos = moved;
    }

    fn relaxed(&self, v: u32, step: f64, cos_turn: f64) -> Option<DVec3> {
        if self.boundary[v as usize] || self.on_crease[v as usize] {
            return None;
        }
        let fan = &self.vfaces[v as usize];
        let (mut weighted, mut area, mut n) = (DVec3::ZERO, 0.0, DVec3::ZERO);
        for &f in fan {
            let tri = self.corners(f);
            let fn_ = triangle_area_normal(tri);
            let a = 0.5 * fn_.length();
            weighted += a * (tri[0] + tri[1] + tri[2]) / 3.0;
            area += a;
            n += fn_;
        }
        let n = n.try_normalize()?;
        if area <= 0.0 {
            return None;
        }
        let p = self.pos[v as usize];
        let d = weighted / area - p;
        let target = p + step * (d - n * n.dot(d));
        let landed = self.onto_data(v, target).unwrap_or(target);
        // The move is kept only if no face of the fan turns far (or over).
        let turned = fan.iter().any(|&f| {
            let before = self.corners(f);
            let after =
                self.faces[f as usize].map(|x| if x == v { landed } else { self.pos[x as usize] });
            let (n0, n1) = (triangle_area_normal(before), triangle_area_normal(after));
            n0.dot(n1) < cos_turn * n0.length() * n1.length()
        });
        (!turned).then_some(landed)
    }

    /// The closest point to `q` on the data triangles around the nearest data point landed
    /// on `v`'s faces (the data this control vertex stands for), if there is one.
    fn onto_data(&self, v: u32, q: DVec3) -> Option<DVec3> {
        let nearest = self.vfaces[v as usize]
            .iter()
            .flat_map(|&f| self.face_points[f as usize].iter().copied())
            .min_by(|&a, &b| {
                let d = |p: u32| self.data.positions[p as usize].distance_squared(q);
                d(a).total_cmp(&d(b))
            })?;
        self.data_faces[nearest as usize]
            .iter()
            .map(|&t| {
                let [a, b, c] =
                    self.data.triangles[t as usize].map(|x| self.data.positions[x as usize]);
                closest_on_triangle(q, a, b, c)
            })
            .min_by(|x, y| x.distance_squared(q).total_cmp(&y.distance_squared(q)))
    }

    /// Moves every data point to the nearest face among those sharing a corner with its
    /// current face.
    fn reland(&mut self) {
        for _ in 0..RELAND_PASSES {
            let this = &*self;
            let land: Vec<(u32, [f64; 3])> = (0..this.land.len())
                .into_par_iter()
                .map(|p| {
                    let (f, _) = this.land[p];
                    let mut near: Vec<u32> = this.faces[f as usize]
                        .iter()
                        .flat_map(|&c| this.vfaces[c as usize].iter().copied())
                        .collect();
                    near.sort_unstable();
                    near.dedup();
                    this.nearest_face(this.data.positions[p], &near)
                })
                .collect();
            for list in &mut self.face_points {
                list.clear();
            }
            for (p, &(f, _)) in land.iter().enumerate() {
                self.face_points[f as usize].push(p as u32);
            }
            self.land = land;
        }
    }

    /// The control mesh and each data point's landing on it.
    pub(super) fn finish(self) -> (TriMesh, Vec<SurfaceParam>, Vec<[u32; 2]>) {
        let landing = self
            .land
            .iter()
            .map(|&(face, b)| SurfaceParam {
                face,
                u: b[0],
                v: b[1],
            })
            .collect();
        let mut creases: Vec<[u32; 2]> = self.creases.into_iter().collect();
        creases.sort_unstable();
        (TriMesh::new(self.pos, self.faces), landing, creases)
    }
}

#[cfg(test)]
#[path = "layout_tests.rs"]
pub(super) mod tests;
