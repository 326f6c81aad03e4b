//! Evaluation pieces shared by root faces and quadtree nodes: box-spline patches over a
//! net, the child maps of the quadtree with their Jacobians, and the depth-cap fallback.

use super::net::{Net, Term};
use crate::surface::box_spline::{
    bezier_ordinates, evaluate_ordinates, stencil_values, stencil_weights,
};
use crate::surface::Derivatives;
use glam::DVec3;

/// Stencil weights of a regular patch as a matrix over a list of columns.
#[derive(Debug)]
pub(super) struct RegularPatch {
    pub cols: Vec<u32>,
    /// 12 x cols row-major, or `None` when stencil point k is exactly column k.
    mat: Option<Vec<f64>>,
    /// For a quadtree node: the matrix holds the stencil points' differences from the
    /// node's base weights, which the value adds once (see `Net`).
    base: Option<Vec<f64>>,
}

impl RegularPatch {
    /// `absolute`: fold the base into the matrix (exact at a root face, whose weights are
    /// unit vectors); otherwise keep it apart.
    pub fn new(net: &Net, stencil: &[Vec<Term>], absolute: bool, map: impl Fn(u32) -> u32) -> Self {
        let nsup = net.nsup;
        let mut dense = vec![0.0; 12 * nsup];
        for (k, terms) in stencil.iter().enumerate() {
            let row = &mut dense[k * nsup..(k + 1) * nsup];
            net.add_diff(terms, 1.0, row);
            if absolute {
                // Stencil terms sum to 1 (ghosts are v + a - b).
                for (r, b) in row.iter_mut().zip(&net.base) {
                    *r += b;
                }
            }
        }
        let used: Vec<usize> = (0..nsup)
            .filter(|&s| {
                (0..12).any(|k| dense[k * nsup + s] != 0.0) || (!absolute && net.base[s] != 0.0)
            })
            .collect();
        // A plain stencil (every row a distinct unit column) needs no matrix.
        let unit: Option<Vec<u32>> = (0..12)
            .map(|k| {
                let row = &dense[k * nsup..(k + 1) * nsup];
                let nz: Vec<usize> = (0..nsup).filter(|&s| row[s] != 0.0).collect();
                (nz.len() == 1 && row[nz[0]] == 1.0).then(|| map(nz[0] as u32))
            })
            .collect();
        if let Some(cols) = unit.filter(|_| absolute && used.len() == 12) {
            return Self {
                cols,
                mat: None,
                base: None,
            };
        }
        let mut mat = Vec::with_capacity(12 * used.len());
        for k in 0..12 {
            mat.extend(used.iter().map(|&s| dense[k * nsup + s]));
        }
        Self {
            cols: used.iter().map(|&s| map(s as u32)).collect(),
            mat: Some(mat),
            base: (!absolute).then(|| used.iter().map(|&s| net.base[s]).collect()),
        }
    }

    /// Adds the patch's rows at local (a, b), derivatives mapped by `jac`, to `acc`
    /// (indexed by column position).
    pub(crate) fn add_rows(&self, a: f64, b: f64, jac: &Jac, acc: &mut [[f64; 6]]) {
        let sw = stencil_weights(a, b, false, 1.0);
        match &self.mat {
            None => {
                for (k, w) in sw.iter().enumerate() {
                    add6(&mut acc[k], &jac.apply(w), 1.0);
                }
            }
            Some(mat) => {
                let n = self.cols.len();
                for (k, w) in sw.iter().enumerate() {
                    let t = jac.apply(w);
                    for (c, slot) in acc.iter_mut().enumerate().take(n) {
                        let m = mat[k * n + c];
                        if m != 0.0 {
                            add6(slot, &t, m);
                        }
                    }
                }
            }
        }
        // The value weights of the stencil sum to 1, their derivatives to 0.
        if let Some(base) = &self.base {
            for (slot, b) in acc.iter_mut().zip(base) {
                slot[0] += b;
            }
        }
    }
}

impl RegularPatch {
    /// The patch's Bezier ordinates for positions of its columns, less the base point, and
    /// the base point (zero at a root face): kept apart so that derivatives deep in the
    /// quadtree come from differences only (see `Net`).
    pub(crate) fn ordinates(&self, position: impl Fn(u32) -> DVec3) -> ([DVec3; 15], DVec3) {
        let mut stencil = [DVec3::ZERO; 12];
        match &self.mat {
            None => {
                for (s, &c) in stencil.iter_mut().zip(&self.cols) {
                    *s = position(c);
                }
            }
            Some(mat) => {
                let n = self.cols.len();
                for (c, &col) in self.cols.iter().enumerate() {
                    let p = position(col);
                    for (k, s) in stencil.iter_mut().enumerate() {
                        let m = mat[k * n + c];
                        if m != 0.0 {
                            *s += p * m;
                        }
                    }
                }
            }
        }
        let base = match &self.base {
            Some(b) => self
                .cols
                .iter()
                .zip(b)
                .map(|(&c, &w)| position(c) * w)
                .sum(),
            None => DVec3::ZERO,
        };
        (bezier_ordinates(&stencil), base)
    }

    /// Adds the value weights alone at local (a, b) to `acc` (indexed by column position).
    pub(crate) fn add_values(&self, a: f64, b: f64, acc: &mut [f64]) {
        let sv = stencil_values(a, b);
        match &self.mat {
            None => {
                for (slot, w) in acc.iter_mut().zip(&sv) {
                    *slot += w;
                }
            }
            Some(mat) => {
                let n = self.cols.len();
                for (k, w) in sv.iter().enumerate() {
                    for (c, slot) in acc.iter_mut().enumerate().take(n) {
                        *slot += mat[k * n + c] * w;
                    }
                }
            }
        }
        if let Some(base) = &self.base {
            for (slot, b) in acc.iter_mut().zip(base) {
                *slot += b;
            }
        }
    }
}

/// Position and face derivatives from a patch's ordinates (less `base`) at local (a, b).
pub(super) fn evaluate_patch(
    ords: &[DVec3; 15],
    base: DVec3,
    a: f64,
    b: f64,
    jac: &Jac,
) -> Derivatives {
    let mut d = jac.apply_derivatives(&evaluate_ordinates(ords, a, b, false, 1.0));
    d.position += base;
    d
}

pub(super) fn add6(acc: &mut [f64; 6], w: &[f64; 6], s: f64) {
    for (a, x) in acc.iter_mut().zip(w) {
        *a += s * x;
    }
}

/// Jacobian of the local parameter of a quadtree node with respect to the face parameter.
#[derive(Clone, Copy, Debug)]
pub(super) struct Jac([[f64; 2]; 2]);

impl Jac {
    pub(crate) const ID: Jac = Jac([[1.0, 0.0], [0.0, 1.0]]);

    pub fn then(&self, j: [[f64; 2]; 2]) -> Jac {
        let m = &self.0;
        let mut r = [[0.0; 2]; 2];
        for (i, row) in r.iter_mut().enumerate() {
            for (k, x) in row.iter_mut().enumerate() {
                *x = j[i][0] * m[0][k] + j[i][1] * m[1][k];
            }
        }
        Jac(r)
    }

    /// `apply` for evaluated derivatives.
    pub fn apply_derivatives(&self, d: &Derivatives) -> Derivatives {
        let [[j00, j01], [j10, j11]] = self.0;
        Derivatives {
            position: d.position,
            du: d.du * j00 + d.dv * j10,
            dv: d.du * j01 + d.dv * j11,
            duu: d.duu * (j00 * j00) + d.duv * (2.0 * j00 * j10) + d.dvv * (j10 * j10),
            duv: d.duu * (j00 * j01) + d.duv * (j00 * j11 + j10 * j01) + d.dvv * (j10 * j11),
            dvv: d.duu * (j01 * j01) + d.duv * (2.0 * j01 * j11) + d.dvv * (j11 * j11),
        }
    }

    /// Local [value, da, db, daa, dab, dbb] to face [value, du, dv, duu, duv, dvv]:
    /// the gradient by J^T, the Hessian by J^T H J (the maps are affine).
    pub fn apply(&self, w: &[f64; 6]) -> [f64; 6] {
        let [[j00, j01], [j10, j11]] = self.0;
        let (da, db, daa, dab, dbb) = (w[1], w[2], w[3], w[4], w[5]);
        [
            w[0],
            j00 * da + j10 * db,
            j01 * da + j11 * db,
            j00 * j00 * daa + 2.0 * j00 * j10 * dab + j10 * j10 * dbb,
            j00 * j01 * daa + (j00 * j11 + j10 * j01) * dab + j10 * j11 * dbb,
            j01 * j01 * daa + 2.0 * j01 * j11 * dab + j11 * j11 * dbb,
        ]
    }
}

/// The child of a node containing local (a, b), the child's local parameter and the
/// Jacobian of the child map. Child 3 (the middle one) is flipped.
pub(super) fn pick_child(a: f64, b: f64) -> (usize, f64, f64, [[f64; 2]; 2]) {
    let w = 1.0 - a - b;
    let (c, na, nb, j) = if a >= 0.5 {
        (0, 2.0 * a - 1.0, 2.0 * b, [[2.0, 0.0], [0.0, 2.0]])
    } else if b >= 0.5 {
        (1, 2.0 * b - 1.0, 2.0 * w, [[0.0, 2.0], [-2.0, -2.0]])
    } else if w >= 0.5 {
        (2, 2.0 * w - 1.0, 2.0 * a, [[-2.0, -2.0], [2.0, 0.0]])
    } else {
        (3, 1.0 - 2.0 * w, 1.0 - 2.0 * a, [[2.0, 2.0], [-2.0, 0.0]])
    };
    let na = na.clamp(0.0, 1.0);
    (c, na, nb.clamp(0.0, 1.0 - na), j)
}

/// A regular node's patch rows, its columns being support columns.
pub(super) fn add_patch_rows(rp: &RegularPatch, a: f64, b: f64, jac: &Jac, acc: &mut [[f64; 6]]) {
    let mut local = [[0.0; 6]; 64];
    let n = rp.cols.len();
    if n <= local.len() {
        rp.add_rows(a, b, jac, &mut local[..n]);
        for (c, w) in rp.cols.iter().zip(&local[..n]) {
            add6(&mut acc[*c as usize], w, 1.0);
        }
    } else {
        let mut big = vec![[0.0; 6]; n];
        rp.add_rows(a, b, jac, &mut big);
        for (c, w) in rp.cols.iter().zip(&big) {
            add6(&mut acc[*c as usize], w, 1.0);
        }
    }
}

/// At the depth cap the node is within 2^-cap of an irregular vertex in parameter and its
/// image is below f64 resolution (see the cap), so the linear interpolation of the exact
/// limit positions of its corners is exact to rounding. Its derivatives are the secant
/// plane's (the tangent plane's direction to within the node's size); second derivatives 0.
pub(super) fn cap_rows(net: &Net, a: f64, b: f64, jac: &Jac, acc: &mut [[f64; 6]]) {
    let w = [
        [a, 1.0, 0.0, 0.0, 0.0, 0.0],
        [b, 0.0, 1.0, 0.0, 0.0, 0.0],
        [1.0 - a - b, -1.0, -1.0, 0.0, 0.0, 0.0],
    ];
    let mut diff = vec![0.0; net.nsup];
    for (c, wc) in w.iter().enumerate() {
        let t = jac.apply(wc);
        let mask = net
            .vertex_rule(c as u32)
            .expect("node corners have complete rings")
            .limit_mask(c as u32, net);
        diff.iter_mut().for_each(|x| *x = 0.0);
        net.add_diff(&mask, 1.0, &mut diff);
        for (slot, r) in acc.iter_mut().zip(&diff) {
            if *r != 0.0 {
                add6(slot, &t, *r);
            }
        }
    }
    // The interpolation weights sum to 1 and each mask to 1: the base enters the value once.
    for (slot, b) in acc.iter_mut().zip(&net.base) {
        slot[0] += b;
    }
}

/// Adds the combination `terms` of net vertices to column `col` of `acc`: with the base
/// when the coefficients sum to 1 (a mask), without when they sum to 0 (a tangent).
pub(super) fn add_column(net: &Net, terms: &[Term], col: usize, acc: &mut [[f64; 6]]) {
    let mut diff = vec![0.0; net.nsup];
    net.add_diff(terms, 1.0, &mut diff);
    let total: f64 = terms.iter().map(|t| t.1).sum();
    for ((slot, d), b) in acc.iter_mut().zip(&diff).zip(&net.base) {
        slot[col] += d + total * b;
    }
}
