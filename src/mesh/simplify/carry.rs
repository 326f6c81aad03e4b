//! The input points carried along the collapses (the module docs of `simplify`), on a
//! thread of its own beside them.
//!
//! No collapse decision reads where the points are, so the carrying needs only each
//! collapse's new fan as it was at the time: the collapsing thread sends it and goes on,
//! and the carrying thread replays the fans in the same order. The landings are the ones
//! carrying in line gives, bit for bit, and the two halves of the work, each about half of
//! a simplification, overlap on two cores.

use super::vertex::FaceList;
use crate::mesh::distance::{barycentric_on, closest_on_triangle};
use crossbeam_channel::Receiver;
use glam::DVec3;

/// Collapses as the carrying sees them, a batch at a time (a message per collapse put the
/// channel's sends, receives and wake-ups at about 4 % of a 139k-point fit's CPU in a
/// profile; a batch pays them once per 256 collapses): per collapse, the faces around the
/// kept vertex after it, in its face list's order, their corners' positions then, and the
/// faces it changed or removed, whose points move onto the fan.
#[derive(Default)]
pub(super) struct Fans {
    faces: Vec<u32>,
    triangles: Vec<[DVec3; 3]>,
    affected: Vec<u32>,
    /// Per collapse, where its faces and its affected faces end.
    ends: Vec<(u32, u32)>,
}

impl Fans {
    /// Collapses a batch holds before it is sent.
    pub const BATCH: usize = 256;

    pub fn len(&self) -> usize {
        self.ends.len()
    }

    pub fn push(&mut self, fan: impl Iterator<Item = (u32, [DVec3; 3])>, affected: &[u32]) {
        for (f, t) in fan {
            self.faces.push(f);
            self.triangles.push(t);
        }
        self.affected.extend_from_slice(affected);
        self.ends
            .push((self.faces.len() as u32, self.affected.len() as u32));
    }

    /// The collapses in order: (fan faces, their triangles, affected faces).
    fn iter(&self) -> impl Iterator<Item = (&[u32], &[[DVec3; 3]], &[u32])> {
        let starts = std::iter::once((0, 0)).chain(self.ends.iter().copied());
        starts.zip(&self.ends).map(|((f0, a0), &(f1, a1))| {
            let (f0, f1, a0, a1) = (f0 as usize, f1 as usize, a0 as usize, a1 as usize);
            (
                &self.faces[f0..f1],
                &self.triangles[f0..f1],
                &self.affected[a0..a1],
            )
        })
    }
}

/// Where every input point lies: a face of the mesh being simplified (input face indices)
/// and its barycentric weights there.
pub(super) struct Landings<'a> {
    input: &'a [DVec3],
    pub face: Vec<u32>,
    pub bary: Vec<[f64; 3]>,
    face_points: Vec<Vec<u32>>,
    /// A collapse's fan balls and moving points, kept between collapses (buffers only).
    balls: Vec<(DVec3, f64)>,
    moving: Vec<u32>,
}

/// A ball holding the triangle: its centroid, and the distance to its furthest corner
/// (a little more, for rounding).
pub(super) fn bounding_ball(t: [DVec3; 3]) -> (DVec3, f64) {
    let centre = (t[0] + t[1] + t[2]) / 3.0;
    let radius = t.iter().map(|c| c.distance(centre)).fold(0.0, f64::max);
    (centre, radius * (1.0 + 1e-12))
}

impl<'a> Landings<'a> {
    /// Every point on the first face of its own (`vfaces[v][0]`), at that corner.
    pub fn new(input: &'a [DVec3], triangles: &[[u32; 3]], vfaces: &[FaceList]) -> Self {
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
            balls: Vec::new(),
            moving: Vec::new(),
        }
    }

    /// Points already landed on a mesh of `faces` faces (an earlier simplification's
    /// landings: `halves`).
    pub fn landed(input: &'a [DVec3], face: Vec<u32>, bary: Vec<[f64; 3]>, faces: usize) -> Self {
        let mut face_points = vec![Vec::new(); faces];
        for (p, &f) in face.iter().enumerate() {
            face_points[f as usize].push(p as u32);
        }
        Self {
            input,
            face,
            bary,
            face_points,
            balls: Vec::new(),
            moving: Vec::new(),
        }
    }

    /// Replays the fans in the order they come until the sender is dropped.
    pub fn carry_all(mut self, batches: Receiver<Fans>) -> (Vec<u32>, Vec<[f64; 3]>) {
        for batch in batches {
            for (faces, triangles, affected) in batch.iter() {
                self.carry(faces, triangles, affected);
            }
        }
        (self.face, self.bary)
    }

    /// Re-projects the points of the affected faces onto the nearest face of the fan (the
    /// first in fan order on a tie). Most points stay on or beside the face they were on,
    /// so a fan face whose bounding ball lies further from the point than that face (or
    /// than the nearest face found so far) cannot win and is not projected onto: the same
    /// faces win as when every fan face is tried.
    fn carry(&mut self, faces: &[u32], triangles: &[[DVec3; 3]], affected: &[u32]) {
        let Some(&first) = faces.first() else {
            return;
        };
        let mut balls = std::mem::take(&mut self.balls);
        balls.clear();
        balls.extend(triangles.iter().map(|t| bounding_ball(*t)));
        let mut points = std::mem::take(&mut self.moving);
        points.clear();
        for &f in affected {
            points.append(&mut self.face_points[f as usize]);
        }
        // Only distances decide the face: the barycentric weights are taken on the
        // winner alone, from the same closest point.
        let closest = |q: DVec3, t: [DVec3; 3]| {
            let on = closest_on_triangle(q, t[0], t[1], t[2]);
            ((on - q).length_squared(), on)
        };
        for &p in &points {
            let q = self.input[p as usize];
            let was_on = faces.iter().position(|&f| f == self.face[p as usize]);
            let on_own = was_on.map(|i| (i, closest(q, triangles[i])));
            let bound = on_own.map_or(f64::INFINITY, |(_, (d2, _))| d2);
            let mut best = (f64::INFINITY, 0, q);
            for (i, &(centre, radius)) in balls.iter().enumerate() {
                let gap = q.distance(centre) - radius;
                // The slack covers the rounding of the distances compared.
                if gap > 0.0 && gap * gap > best.0.min(bound) * (1.0 + 1e-9) {
                    continue;
                }
                let (d2, on) = match on_own {
                    Some((own, projected)) if own == i => projected,
                    _ => closest(q, triangles[i]),
                };
                if d2 < best.0 {
                    best = (d2, i, on);
                }
            }
            let (face, bary) = if best.0.is_finite() {
                (faces[best.1], barycentric_on(best.2, triangles[best.1]))
            } else {
                (first, [1.0, 0.0, 0.0])
            };
            self.face[p as usize] = face;
            self.bary[p as usize] = bary;
            self.face_points[face as usize].push(p);
        }
        self.balls = balls;
        self.moving = points;
    }
}
