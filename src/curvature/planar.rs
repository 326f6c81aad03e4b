//! Curvature of a DMS triangular B-spline (`surface.json` kind `dms`): one global chart, the
//! domain points (x, y) themselves, with derivatives in x and y straight from the simplex
//! splines' jets. The sampling is a lattice per domain triangle, welded along shared edges
//! and at shared vertices so that regions and their boundary loops cross triangles.

use super::{DerivativeSurface, Domain, OwnLattice};
use crate::surface::bezier::{lattice_points, lattice_triangles};
use crate::surface::dms::{DmsSpline, PlanarSurface};
use crate::surface::Derivatives;
use glam::{DVec2, DVec3};
use rustc_hash::FxHashMap;
use std::sync::Arc;

/// A DMS spline and its controls, parameterised by domain points.
pub struct DmsPatch {
    /// The spline.
    pub spline: Arc<DmsSpline>,
    /// Its control points.
    pub controls: Vec<DVec3>,
}

impl DerivativeSurface for DmsPatch {
    fn domain(&self) -> Domain {
        Domain::Cells
    }

    /// Outside the domain: zero derivatives (the lattice never samples there).
    fn derivatives(&self, x: f64, y: f64) -> Derivatives {
        let x = DVec2::new(x, y);
        let Some(p) = self.spline.locate(x) else {
            return Derivatives::default();
        };
        // Knot lines resolve towards the centre of the triangle holding the point.
        let corners =
            self.spline.triangles()[p.face as usize].map(|v| self.spline.vertices()[v as usize]);
        let dir = (corners[0] + corners[1] + corners[2]) / 3.0 - x;
        let mut rows = Vec::new();
        self.spline.basis_at::<true>(x, dir, &mut rows);
        let mut sum = [DVec3::ZERO; 6];
        for (i, jet) in &rows {
            let c = self.controls.get(*i as usize).copied().unwrap_or_default();
            for (s, w) in sum.iter_mut().zip(jet) {
                *s += c * *w;
            }
        }
        Derivatives {
            position: sum[0],
            du: sum[1],
            dv: sum[2],
            duu: sum[3],
            duv: sum[4],
            dvv: sum[5],
        }
    }

    fn own_lattice(&self, n: usize) -> OwnLattice {
        let triangles = self.spline.triangles();
        let per = ((n as f64 / (triangles.len().max(1) as f64).sqrt()).ceil() as usize).max(2);
        let local = lattice_points(per);
        let local_tris = lattice_triangles(per);
        let vertices = self.spline.vertices();
        let mut index: FxHashMap<[(u32, usize); 3], u32> = FxHashMap::default();
        let mut params = Vec::new();
        let mut out = Vec::with_capacity(triangles.len() * local_tris.len());
        for t in triangles {
            let ids: Vec<u32> = local
                .iter()
                .map(|&(i, j)| {
                    // The point's weights on the corners, sorted by vertex: the same key
                    // (and the same arithmetic) from every triangle sharing the point.
                    let mut key = [(t[0], i), (t[1], j), (t[2], per - i - j)];
                    for entry in &mut key {
                        if entry.1 == 0 {
                            *entry = (u32::MAX, 0);
                        }
                    }
                    key.sort_unstable();
                    *index.entry(key).or_insert_with(|| {
                        let x = key
                            .iter()
                            .filter(|(v, _)| *v != u32::MAX)
                            .map(|&(v, w)| vertices[v as usize] * w as f64)
                            .sum::<DVec2>()
                            / per as f64;
                        params.push((x.x, x.y));
                        (params.len() - 1) as u32
                    })
                })
                .collect();
            out.extend(local_tris.iter().map(|l| l.map(|k| ids[k as usize])));
        }
        OwnLattice {
            params,
            triangles: out,
            charts: None,
        }
    }
}
