//! Squared-distance minimisation (point-to-plane with a tangential share) at fixed foot
//! points: minimise
//!     sum_j (n_j . r_j)^2 + t_j |r_j|^2 + r_j^T C_j r_j  +  s |L P|^2,  r_j = S(u_j) - p_j
//! over the control points P, where u_j are foot points of the data on the current surface
//! and n_j the surface normals there; C_j, where given, is the curvature's tangential term
//! of the squared distance (`pipeline::geometric::curvature_term`, SDM). Unlike point-to-point fitting with parameter
//! correction, the surface may slide along itself at no cost, so a few rounds reach what
//! many rounds of parameter correction approach slowly. `t_j` keeps the system definite
//! where the normals alone leave a direction free (flat regions, no data), and sets how
//! freely the surface slides at point j (`pipeline::edge_band` picks it per point).
//!
//! Solved by conjugate gradients on the (symmetric positive definite) normal equations,
//! with the three coordinates coupled through n_j n_j^T, preconditioned by the 3x3 diagonal
//! blocks: with a small `t` the system is ~1/t times stiffer along the normals than along
//! the surface, and the blocks, which see each control's local normal, take most of that
//! spread out of the iteration. The rounds of a fit (`solve_distance_round`) factorise
//! small systems and start CG from the previous round's controls on large ones.

use super::collocation::Collocation;
use super::csr::Csr;
use super::normal_matrix::{BlockMatrix, Fairness};
pub(crate) use super::normal_solve::CholeskyPattern;
use glam::DVec3;

pub(crate) struct DistanceProblem<'a> {
    /// The collocation rows at the foot points.
    pub basis: &'a Csr,
    pub data: &'a [DVec3],
    /// Unit surface normals at the foot points, one per data point.
    pub normals: &'a [DVec3],
    /// Per data point: weight of the full point-to-point term beside the point-to-plane one.
    pub tangential: &'a [f64],
    /// Per data point, or none: the curvature's tangential term of the squared distance
    /// (`pipeline::geometric::curvature_term`), added to the weight.
    pub curvature: Option<&'a [[f64; 6]]>,
    pub fairness: Option<&'a Collocation>,
    pub smoothing: f64,
}

impl DistanceProblem<'_> {
    fn assemble(&self, lower_only: bool) -> BlockMatrix {
        let fairness = self.fairness.map(|l| Fairness {
            l: l.n(),
            lt: l.nt(),
            smoothing: self.smoothing,
        });
        BlockMatrix::assemble(
            self.basis,
            self.data,
            self.normals,
            (self.tangential, self.curvature),
            fairness,
            lower_only,
        )
    }

    /// M x = N^T W N x + s L^T L x without assembling M: the reference the assembled
    /// blocks are tested against.
    #[cfg(test)]
    fn apply(&self, x: &[DVec3], out: &mut [DVec3]) {
        let mut nx = vec![DVec3::ZERO; self.basis.nrows];
        self.basis.mul_vec3(x, &mut nx);
        nx.iter_mut()
            .zip(self.normals)
            .zip(self.tangential)
            .for_each(|((r, n), t)| *r = *n * n.dot(*r) + *r * *t);
        Collocation::new(self.basis.clone()).mul_t_vec3(&nx, out);
        if let Some(l) = self.fairness.filter(|_| self.smoothing > 0.0) {
            let mut lx = vec![DVec3::ZERO; l.nrows()];
            l.mul_vec3(x, &mut lx);
            let mut ltlx = vec![DVec3::ZERO; x.len()];
            l.mul_t_vec3(&lx, &mut ltlx);
            out.iter_mut()
                .zip(&ltlx)
                .for_each(|(o, v)| *o += *v * self.smoothing);
        }
    }
}

/// Block-preconditioned conjugate gradients from `start` until the residual of the normal
/// equations drops by `rel_tol` or `max_iter` steps; returns the controls and the steps.
pub(crate) fn solve_distance(
    p: &DistanceProblem,
    start: Vec<DVec3>,
    max_iter: usize,
    rel_tol: f64,
) -> (Vec<DVec3>, usize) {
    p.assemble(false).solve_pcg(start, max_iter, rel_tol)
}

/// The same minimiser by a sparse Cholesky factorisation of the 3m x 3m normal matrix
/// (faer, fill-reducing ordering): on small nets one factorisation costs less than the
/// 25-45 preconditioned CG steps a round needs, and it is exact. `None` when the matrix is
/// not positive definite (controls no term holds): callers fall back to `solve_distance`.
pub(crate) fn solve_distance_direct(p: &DistanceProblem) -> Option<Vec<DVec3>> {
    p.assemble(true).solve_direct().ok()
}

/// Steps of warm-started CG before a round factorises its matrix instead. Measured from
/// the previous round's controls, CG reached a relative residual of 1e-10 in 71-101 steps
/// on the rounds of bun_zipper (1047-1712 controls) and of a 139k-point object
/// (4174-6898).
const WARM_CG_MAX_STEPS: usize = 250;

/// Controls from which a round tries warm-started CG first. Below, a factorisation takes
/// a few milliseconds and is exact to rounding; CG to `WARM_CG_REL_TOL` moved the fits of
/// the coarse models (fertility's 225 controls, decimated-max's 264) by up to 1 % RMS,
/// which the refinement then carries on.
const WARM_CG_MIN_CONTROLS: usize = 1000;

/// Residual (relative to b) at which warm-started CG stands for a factorisation. b is of
/// the size of the controls themselves, while a round moves them by about 1e-3 of that
/// and less in the late rounds: this leaves the step right to within a thousandth of
/// itself (the unit test below), finer than the rounds' own progress, where 1e-10 took
/// about twice the steps. Against 1e-10 (CLI defaults; the refinement's choices move with
/// any change of the rounds, as they do with the data's order): bun_zipper 63.67 um at
/// 1713 controls against 63.89 at 1719, a 139k-point noisy bunny 44.257 against 44.256
/// um at 4174, CGAL's armadillo 0.1531 against 0.1541 and bunny00 2.75099e-4 against
/// 2.75096e-4 at the same controls, the rounds' time 5-20 % lower. (1e-8 moved the fits
/// as much, bun_zipper 63.26 um, armadillo 0.1556, and saved 1-10 %.)
const WARM_CG_REL_TOL: f64 = 1e-7;

/// One round of a sequence of problems over the same controls (the rounds of one fit).
/// From `start` (the previous round's controls, close to the solution because the foot
/// points move by a fraction of a control spacing between rounds) by block-preconditioned
/// CG to `WARM_CG_REL_TOL`; by a factorisation through the kept symbolic analysis
/// (`pattern`) without a start or when CG does not get there in `WARM_CG_MAX_STEPS`.
///
/// Why CG first: a numeric factorisation costs the same whatever the start, and its fill
/// grows faster than the controls. On the 20.7k-unknown rounds of a 139k-point object it
/// took 150-280 ms besides the assembly, CG 20-60 ms; on bun_zipper's 5k unknowns the
/// whole solve took 28-50 ms against 17-31 ms. The factor kept from the previous round as
/// CG's preconditioner was tried: it needed 25-39 steps of two triangular solves each,
/// slower than refactorising.
pub(crate) fn solve_distance_round(
    p: &DistanceProblem,
    pattern: &mut CholeskyPattern,
    start: Option<&[DVec3]>,
) -> Option<Vec<DVec3>> {
    let start = start.filter(|s| s.len() >= WARM_CG_MIN_CONTROLS);
    let warm = start.and_then(|start| {
        p.assemble(false)
            .solve_pcg_converged(start.to_vec(), WARM_CG_MAX_STEPS, WARM_CG_REL_TOL)
    });
    if warm.is_some() {
        pattern.warm_cg_solves += 1;
        return warm;
    }
    p.assemble(true).solve_direct_reusing(pattern).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With t = 1 and zero normals the problem is plain least squares: compare with the
    /// normal equations solved densely.
    #[test]
    fn reduces_to_least_squares_and_matches_a_dense_solve() {
        let rows: Vec<Vec<(u32, f64)>> = (0..40)
            .map(|j| {
                let a = (j % 7) as u32;
                vec![
                    (a, 0.6),
                    ((a + 1) % 7, 0.3),
                    ((a + 3) % 7, 0.1 + 0.001 * j as f64),
                ]
            })
            .collect();
        let basis = Csr::from_rows(7, rows.iter().map(|r| r.as_slice()));
        let data: Vec<DVec3> = (0..40)
            .map(|j| DVec3::new(j as f64 * 0.1, (j as f64).sin(), (j * j % 5) as f64))
            .collect();
        let normals = vec![DVec3::ZERO; 40];
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: &[1.0; 40],
            curvature: None,
            fairness: None,
            smoothing: 0.0,
        };
        let (x, _) = solve_distance(&p, vec![DVec3::ZERO; 7], 200, 1e-14);
        let mut a = nalgebra::DMatrix::<f64>::zeros(40, 7);
        for (j, row) in rows.iter().enumerate() {
            for &(c, w) in row {
                a[(j, c as usize)] += w;
            }
        }
        let ata = a.transpose() * &a;
        for axis in 0..3 {
            let rhs = nalgebra::DVector::from_iterator(40, data.iter().map(|d| d[axis]));
            let want = ata
                .clone()
                .cholesky()
                .expect("definite")
                .solve(&(a.transpose() * rhs));
            for c in 0..7 {
                assert!(
                    (x[c][axis] - want[c]).abs() < 1e-9,
                    "{} vs {}",
                    x[c][axis],
                    want[c]
                );
            }
        }
    }

    /// Point-to-plane only moves controls along the normals: data displaced tangentially
    /// leave a plane fit where it is.
    #[test]
    fn tangential_offsets_cost_nothing_without_the_tangential_share() {
        let rows: Vec<Vec<(u32, f64)>> = (0..20).map(|j| vec![((j % 4) as u32, 1.0)]).collect();
        let basis = Csr::from_rows(4, rows.iter().map(|r| r.as_slice()));
        let data: Vec<DVec3> = (0..20)
            .map(|j| DVec3::new((j % 3) as f64, (j % 5) as f64, 0.25))
            .collect();
        let normals = vec![DVec3::Z; 20];
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: &[0.0; 20],
            curvature: None,
            fairness: None,
            smoothing: 0.0,
        };
        let start = vec![DVec3::new(9.0, -3.0, 0.0); 4];
        let (x, _) = solve_distance(&p, start, 100, 1e-14);
        for c in &x {
            assert!(
                (c.z - 0.25).abs() < 1e-12 && c.x == 9.0 && c.y == -3.0,
                "{c}"
            );
        }
    }
    /// The coupled system with a small tangential share and varied normals (what the
    /// block preconditioner is for) against a dense solve of the 3m x 3m normal equations.
    #[test]
    fn coupled_system_matches_a_dense_solve() {
        let m = 9;
        let rows: Vec<Vec<(u32, f64)>> = (0..60)
            .map(|j| {
                let a = (j % m) as u32;
                vec![
                    (a, 0.5),
                    ((a + 1) % m as u32, 0.3),
                    ((a + 4) % m as u32, 0.2),
                ]
            })
            .collect();
        let basis = Csr::from_rows(m, rows.iter().map(|r| r.as_slice()));
        let data: Vec<DVec3> = (0..60)
            .map(|j| {
                DVec3::new(
                    (j as f64 * 0.7).sin(),
                    (j as f64 * 0.3).cos(),
                    j as f64 * 0.01,
                )
            })
            .collect();
        let normals: Vec<DVec3> = (0..60)
            .map(|j| DVec3::new(0.3 * (j as f64).sin(), 0.2, 1.0).normalize())
            .collect();
        let t: Vec<f64> = (0..60).map(|j| [0.02, 0.002][j % 2]).collect();
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: &t,
            curvature: None,
            fairness: None,
            smoothing: 0.0,
        };
        let (x, steps) = solve_distance(&p, vec![DVec3::ZERO; m], 500, 1e-13);
        assert!(steps < 500, "converged");
        let mut mat = nalgebra::DMatrix::<f64>::zeros(3 * m, 3 * m);
        let mut rhs = nalgebra::DVector::<f64>::zeros(3 * m);
        for (j, row) in rows.iter().enumerate() {
            let n = normals[j];
            let w =
                glam::DMat3::from_cols(n * n.x, n * n.y, n * n.z) + glam::DMat3::IDENTITY * t[j];
            let wp = w * data[j];
            for &(a, wa) in row {
                for r in 0..3 {
                    rhs[3 * a as usize + r] += wa * wp[r];
                }
                for &(b, wb) in row {
                    for r in 0..3 {
                        for c in 0..3 {
                            mat[(3 * a as usize + r, 3 * b as usize + c)] += wa * wb * w.col(c)[r];
                        }
                    }
                }
            }
        }
        let want = mat.cholesky().expect("definite").solve(&rhs);
        let direct = solve_distance_direct(&p).expect("definite");
        for c in 0..m {
            for r in 0..3 {
                assert!(
                    (x[c][r] - want[3 * c + r]).abs() < 1e-8,
                    "{} vs {}",
                    x[c][r],
                    want[3 * c + r]
                );
                assert!(
                    (direct[c][r] - want[3 * c + r]).abs() < 1e-10,
                    "direct {} vs {}",
                    direct[c][r],
                    want[3 * c + r]
                );
            }
        }
    }
    /// The assembled blocks (with a fairness term) against the product through N and N^T.
    #[test]
    fn assembled_blocks_equal_the_product_through_the_data() {
        let m = 8;
        let rows: Vec<Vec<(u32, f64)>> = (0..50)
            .map(|j| {
                let a = (j % m) as u32;
                vec![
                    (a, 0.6),
                    ((a + 2) % m as u32, 0.3),
                    ((a + 5) % m as u32, 0.1),
                ]
            })
            .collect();
        let basis = Csr::from_rows(m, rows.iter().map(|r| r.as_slice()));
        let fairness = Collocation::new(crate::fit::csr::ring_laplacian(m, 7));
        let data: Vec<DVec3> = (0..50).map(|j| DVec3::splat(j as f64)).collect();
        let normals: Vec<DVec3> = (0..50)
            .map(|j| DVec3::new((j as f64).cos(), 0.3, (j as f64).sin()).normalize())
            .collect();
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: &(0..50).map(|j| 0.01 * (j % 5) as f64).collect::<Vec<_>>(),
            curvature: None,
            fairness: Some(&fairness),
            smoothing: 0.7,
        };
        let x: Vec<DVec3> = (0..m)
            .map(|c| DVec3::new(c as f64, (c * c) as f64 * 0.1, -(c as f64)))
            .collect();
        let (mut want, mut got) = (vec![DVec3::ZERO; m], vec![DVec3::ZERO; m]);
        p.apply(&x, &mut want);
        p.assemble(false).apply(&x, &mut got);
        for (a, b) in want.iter().zip(&got) {
            assert!(
                (*a - *b).length() < 1e-12 * a.length().max(1.0),
                "{a} vs {b}"
            );
        }
    }
    /// Rounds through one kept analysis: a second matrix on the same pattern reuses it, one
    /// with a coupling outside it is analysed again over the union, and every solve equals
    /// a fresh factorisation's.
    #[test]
    fn kept_analysis_serves_later_patterns_and_solves_alike() {
        let m = 10;
        let rows_of = |extra: bool| -> Vec<Vec<(u32, f64)>> {
            (0..80)
                .map(|j| {
                    let a = (j % m) as u32;
                    let mut row = vec![
                        (a, 0.5 + 0.001 * j as f64),
                        ((a + 1) % m as u32, 0.3),
                        ((a + 2) % m as u32, 0.2),
                    ];
                    if extra && j == 7 {
                        row.push(((a + 5) % m as u32, 0.1));
                    }
                    row.sort_by_key(|e| e.0);
                    row.dedup_by_key(|e| e.0);
                    row
                })
                .collect()
        };
        let data: Vec<DVec3> = (0..80)
            .map(|j| DVec3::new((j as f64 * 0.3).sin(), j as f64 * 0.02, (j as f64).cos()))
            .collect();
        let mut pattern = CholeskyPattern::default();
        for (round, extra) in [false, false, true, false].into_iter().enumerate() {
            let rows = rows_of(extra);
            let basis = Csr::from_rows(m, rows.iter().map(|r| r.as_slice()));
            let normals: Vec<DVec3> = (0..80)
                .map(|j| DVec3::new(0.2, (j as f64 + round as f64).sin() * 0.3, 1.0).normalize())
                .collect();
            let p = DistanceProblem {
                basis: &basis,
                data: &data,
                normals: &normals,
                tangential: &[0.01; 80],
                curvature: None,
                fairness: None,
                smoothing: 0.0,
            };
            // A start changes nothing on so few controls: the factorisation takes the round.
            let start = vec![DVec3::ZERO; m];
            let kept = solve_distance_round(&p, &mut pattern, Some(&start)).expect("definite");
            let fresh = solve_distance_direct(&p).expect("definite");
            for (a, b) in kept.iter().zip(&fresh) {
                assert!(
                    (*a - *b).length() < 1e-10 * b.length().max(1.0),
                    "{a} vs {b}"
                );
            }
        }
        // Rounds 1, 2 and 4 fit the kept pattern; round 3 adds a coupling.
        assert_eq!(
            (pattern.analyses, pattern.reuses, pattern.warm_cg_solves),
            (2, 2, 0)
        );
    }

    /// A round large enough for warm-started CG ends where the factorisation does, from a
    /// start as far off as a round's previous controls and from one much further.
    #[test]
    fn a_warm_started_round_matches_the_factorisation() {
        let m = 2 * WARM_CG_MIN_CONTROLS;
        let n = 6 * m;
        let rows: Vec<Vec<(u32, f64)>> = (0..n)
            .map(|j| {
                let a = (j * 7 % m) as u32;
                let t = (j as f64 * 0.37).sin().abs();
                let mut row = vec![
                    (a, 0.5 + 0.2 * t),
                    ((a + 1) % m as u32, 0.3 - 0.1 * t),
                    ((a + 40) % m as u32, 0.2 - 0.1 * t),
                ];
                row.sort_by_key(|e| e.0);
                row
            })
            .collect();
        let basis = Csr::from_rows(m, rows.iter().map(|r| r.as_slice()));
        let fairness = Collocation::new(crate::fit::csr::ring_laplacian(m, 40));
        let data: Vec<DVec3> = (0..n)
            .map(|j| {
                DVec3::new(
                    (j as f64 * 0.01).sin(),
                    j as f64 * 1e-4,
                    (j as f64 * 0.013).cos(),
                )
            })
            .collect();
        let normals: Vec<DVec3> = (0..n)
            .map(|j| DVec3::new(0.3 * (j as f64).sin(), 0.2, 1.0).normalize())
            .collect();
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: &vec![0.01; n],
            curvature: None,
            fairness: Some(&fairness),
            smoothing: 1e-3,
        };
        let exact = solve_distance_direct(&p).expect("definite");
        let scale = exact.iter().map(|x| x.length()).fold(0.0, f64::max);
        for offset in [1e-3, 0.3] {
            let start: Vec<DVec3> = exact
                .iter()
                .enumerate()
                .map(|(c, x)| *x + DVec3::new((c as f64).sin(), 0.5, (c as f64).cos()) * offset)
                .collect();
            let mut pattern = CholeskyPattern::default();
            let warm = solve_distance_round(&p, &mut pattern, Some(&start)).expect("solved");
            let off = |x: &[DVec3]| {
                x.iter()
                    .zip(&exact)
                    .map(|(a, b)| (*a - *b).length())
                    .fold(0.0, f64::max)
            };
            // Right to a thousandth of the step it took (`WARM_CG_REL_TOL`: 7e-4 here).
            let (worst, step) = (off(&warm), off(&start));
            assert!(worst < 1e-3 * step, "offset {offset}: {worst} of {step}");
            assert!(worst < 1e-5 * scale, "offset {offset}: {worst} of {scale}");
            assert_eq!((pattern.warm_cg_solves, pattern.analyses), (1, 0));
        }
    }
}
