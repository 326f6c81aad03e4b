//! The input points carried along the collapses (the module docs of `simplify`), on a
//! thread of its own beside them.
//!
//! No collapse decision reads where the points are, so the carrying needs only each
//! collapse's new fan as it was at the time: the collapsing thread sends it and goes on,
//! and the carrying thread replays the fans in the same order. The landings are the ones
//! carrying in line gives, bit for bit, and the two halves of the work, each about half of
//! a simplification, overlap on two cores.

use crate::mesh::distance::project_onto_triangle;
use crossbeam_channel::Receiver;
use glam::DVec3;

/// One collapse as the carrying sees it.
pub(super) struct Fan {
    /// The faces around the kept vertex after the collapse, in its face list's order ...
    pub faces: Vec<u32>,
    /// ... and their corners' positions then.
    pub triangles: Vec<[DVec3; 3]>,
    /// The faces the collapse changed or removed: their points move onto the fan.
    pub affected: Vec<u32>,
}

/// Where every input point lies: a face of the mesh being simplified (input face indices)
/// and its barycentric weights there.
pub(super) struct Landings<'a> {
    input: &'a [DVec3],
    pub face: Vec<u32>,
    pub bary: Vec<[f64; 3]>,
    face_points: Vec<Vec<u32>>,
}

/// A ball holding the triangle: its centroid, and the distance to its furthest corner
/// (a little more, for rounding).
fn bounding_ball(t: [DVec3; 3]) -> (DVec3, f64) {
    let centre = (t[0] + t[1] + t[2]) / 3.0;
    let radius = t.iter().map(|c| c.distance(centre)).fold(0.0, f64::max);
    (centre, radius * (1.0 + 1e-12))
}

impl<'a> Landings<'a> {
    /// Every point on the first face of its own (`vfaces[v][0]`), at that corner.
    pub fn new(input: &'a [DVec3], triangles: &[[u32; 3]], vfaces: &[Vec<u32>]) -> Self {
        let nv = input.len();
        let mut face = vec![0u32; nv];
        let mut bary = vec![[0.0; 3]; nv];
        let mut face_points = vec![Vec::new(); triangles.len()];
        for (v, faces) in vfaces.iter().enumerate() {
            let Some(&f) = faces.first() else {
                continue;
            };
            let slot = triangles[f as usize]
                .iter()
                .position(|&c| c as usize == v)
                .unwrap_or(0);
            face[v] = f;
            bary[v][slot] = 1.0;
            face_points[f as usize].push(v as u32);
        }
        Self {
            input,
            face,
            bary,
            face_points,
        }
    }

    /// Replays the fans in the order they come until the sender is dropped.
    pub fn carry_all(mut self, fans: Receiver<Fan>) -> (Vec<u32>, Vec<[f64; 3]>) {
        for fan in fans {
            self.carry(&fan);
        }
        (self.face, self.bary)
    }

    /// Re-projects the points of the affected faces onto the nearest face of the fan (the
    /// first in fan order on a tie). Most points stay on or beside the face they were on,
    /// so a fan face whose bounding ball lies further from the point than that face (or
    /// than the nearest face found so far) cannot win and is not projected onto: the same
    /// faces win as when every fan face is tried.
    fn carry(&mut self, fan: &Fan) {
        let Some(&first) = fan.faces.first() else {
            return;
        };
        let balls: Vec<(DVec3, f64)> = fan.triangles.iter().map(|t| bounding_ball(*t)).collect();
        let mut points = Vec::new();
        for &f in &fan.affected {
            points.append(&mut self.face_points[f as usize]);
        }
        for p in points {
            let q = self.input[p as usize];
            let was_on = fan.faces.iter().position(|&f| f == self.face[p as usize]);
            let on_own = was_on.map(|i| (i, project_onto_triangle(q, fan.triangles[i])));
            let bound = on_own.map_or(f64::INFINITY, |(_, (d2, _))| d2);
            let mut best = (f64::INFINITY, first, [1.0, 0.0, 0.0]);
            for (i, &f) in fan.faces.iter().enumerate() {
                let (centre, radius) = balls[i];
                let gap = q.distance(centre) - radius;
                // The slack covers the rounding of the distances compared.
                if gap > 0.0 && gap * gap > best.0.min(bound) * (1.0 + 1e-9) {
                    continue;
                }
                let (d2, bary) = match on_own {
                    Some((own, projected)) if own == i => projected,
                    _ => project_onto_triangle(q, fan.triangles[i]),
                };
                if d2 < best.0 {
                    best = (d2, f, bary);
                }
            }
            self.face[p as usize] = best.1;
            self.bary[p as usize] = best.2;
            self.face_points[best.1 as usize].push(p);
        }
    }
}
