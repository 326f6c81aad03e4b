//! The fitting iterations: PIA, LSPIA, CG on the normal equations (CGLS), and a direct
//! solve as ground truth. All minimise `|N P - p|^2 + s |L P|^2` (PIA only the first term).

use super::budget::{Budget, FitStatus, StepStats};
use super::normal_matrix::{Fairness, ScalarMatrix};
use super::normal_solve::DirectFailure;
use super::sparse::{Collocation, Csr};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    Pia,
    Lspia,
    Cg,
    Direct,
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "pia" => Ok(Self::Pia),
            "lspia" => Ok(Self::Lspia),
            "cg" => Ok(Self::Cg),
            "direct" => Ok(Self::Direct),
            _ => Err(format!("unknown method '{s}' (pia|lspia|cg|direct)")),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error("method pia needs an inverse-subdivision operator (data on the subdivision lattice)")]
    NoPiaOperator,
    #[error("{0} data points but the collocation matrix has {1} rows")]
    Shape(usize, usize),
    #[error("initial net has {0} points, the surface {1} control points")]
    InitialShape(usize, usize),
    #[error("direct solve: {0}")]
    Direct(String),
}

pub type PiaOperator<'a> = &'a (dyn Fn(&[DVec3]) -> Vec<DVec3> + Sync);

pub struct FitProblem<'a> {
    pub basis: &'a Collocation,
    pub data: &'a [DVec3],
    pub smoothing: f64,
    /// Fairness operator L over control points (with its transpose).
    pub fairness: Option<&'a Collocation>,
    pub pia_operator: Option<PiaOperator<'a>>,
    /// Called with every step's statistics as soon as they exist (k = 0, the starting
    /// net, first), e.g. for a progress bar. Runs on the fitting thread between steps.
    pub on_step: Option<StepHook<'a>>,
}

pub type StepHook<'a> = &'a (dyn Fn(&StepStats) + Sync);

#[derive(Clone, Debug)]
pub struct FitOutcome {
    pub controls: Vec<DVec3>,
    /// k = 0 is the initial net.
    pub steps: Vec<StepStats>,
    pub status: FitStatus,
    pub iterations: usize,
}

/// The stacked operator A = [N; sqrt(s) L] and its transpose.
struct Stacked<'a> {
    p: &'a FitProblem<'a>,
    root_s: f64,
}

impl Stacked<'_> {
    fn fair(&self) -> Option<&Collocation> {
        self.p.fairness.filter(|_| self.root_s > 0.0)
    }
    fn apply(&self, x: &[DVec3], data_part: &mut [DVec3], fair_part: &mut Vec<DVec3>) {
        self.p.basis.mul_vec3(x, data_part);
        if let Some(l) = self.fair() {
            fair_part.resize(l.nrows(), DVec3::ZERO);
            l.mul_vec3(x, fair_part);
            fair_part.iter_mut().for_each(|v| *v *= self.root_s);
        }
    }
    /// Residuals of the stacked system at x: data part p - N x, fairness part -sqrt(s) L x.
    fn residuals(&self, x: &[DVec3], data_part: &mut [DVec3], fair_part: &mut Vec<DVec3>) {
        self.apply(x, data_part, fair_part);
        update(data_part, self.p.data, |r, p| *r = p - *r);
        fair_part.iter_mut().for_each(|v| *v = -*v);
    }

    fn apply_t(&self, data_part: &[DVec3], fair_part: &[DVec3], out: &mut [DVec3]) {
        self.p.basis.mul_t_vec3(data_part, out);
        if let Some(l) = self.fair() {
            let mut tmp = vec![DVec3::ZERO; out.len()];
            l.mul_t_vec3(fair_part, &mut tmp);
            out.iter_mut()
                .zip(&tmp)
                .for_each(|(o, t)| *o += *t * self.root_s);
        }
    }
}

/// Vectors longer than this are reduced and updated in parallel, in fixed chunks so that
/// results do not depend on the thread count.
const VEC_CHUNK: usize = 1 << 16;

fn dot3(a: &[DVec3], b: &[DVec3]) -> DVec3 {
    let seq =
        |(a, b): (&[DVec3], &[DVec3])| -> DVec3 { a.iter().zip(b).map(|(x, y)| *x * *y).sum() };
    if a.len() <= VEC_CHUNK {
        return seq((a, b));
    }
    let parts: Vec<DVec3> = a
        .par_chunks(VEC_CHUNK)
        .zip(b.par_chunks(VEC_CHUNK))
        .map(seq)
        .collect();
    parts.into_iter().sum()
}

/// y = f(y, x) element-wise.
fn update(y: &mut [DVec3], x: &[DVec3], f: impl Fn(&mut DVec3, DVec3) + Sync) {
    if y.len() <= VEC_CHUNK {
        y.iter_mut().zip(x).for_each(|(y, x)| f(y, *x));
    } else {
        y.par_iter_mut()
            .zip(x.par_iter())
            .for_each(|(y, x)| f(y, *x));
    }
}

/// Largest eigenvalue of A^T A by power iteration from the all-ones vector, which for a
/// non-negative N has a large component along the Perron vector.
pub fn lambda_max(
    basis: &Collocation,
    fairness: Option<&Collocation>,
    smoothing: f64,
    iterations: usize,
) -> f64 {
    let nc = basis.ncols();
    let mut x = vec![1.0 / (nc as f64).sqrt(); nc];
    let mut lambda = 0.0;
    let normal = |m: &Collocation, x: &[f64]| -> Vec<f64> {
        let mut mx = vec![0.0; m.nrows()];
        m.mul_scalar(x, &mut mx);
        let mut out = vec![0.0; m.ncols()];
        m.mul_t_scalar(&mx, &mut out);
        out
    };
    for _ in 0..iterations {
        let mut y = normal(basis, &x);
        if let Some(l) = fairness.filter(|_| smoothing > 0.0) {
            let lt = normal(l, &x);
            y.iter_mut().zip(&lt).for_each(|(a, b)| *a += smoothing * b);
        }
        let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm == 0.0 {
            return 0.0;
        }
        lambda = norm;
        x = y.into_iter().map(|v| v / norm).collect();
    }
    lambda
}

pub fn fit(
    problem: &FitProblem,
    initial: Vec<DVec3>,
    method: Method,
    budget: &Budget,
) -> Result<FitOutcome, FitError> {
    let n = problem.basis;
    let (nrows, ncols) = (n.nrows(), n.ncols());
    if problem.data.len() != nrows {
        return Err(FitError::Shape(problem.data.len(), nrows));
    }
    if initial.len() != ncols {
        return Err(FitError::InitialShape(initial.len(), ncols));
    }
    let report = |s: &StepStats| {
        if let Some(hook) = problem.on_step {
            hook(s);
        }
    };
    let start = Instant::now();
    let elapsed = || start.elapsed().as_secs_f64() * 1e3;
    let a = Stacked {
        p: problem,
        root_s: problem.smoothing.max(0.0).sqrt(),
    };
    let mut x = initial;
    let mut r_data = vec![DVec3::ZERO; nrows];
    let mut r_fair = Vec::new();
    a.residuals(&x, &mut r_data, &mut r_fair);
    let mut steps = vec![StepStats::from_residuals(
        0,
        &r_data,
        budget.tolerance,
        elapsed(),
    )];
    report(&steps[0]);
    let time_up = |t: f64| budget.max_time_ms.is_some_and(|m| t >= m as f64);
    let finish = |x: Vec<DVec3>, steps: Vec<StepStats>, status| {
        let iterations = steps.len() - 1;
        Ok(FitOutcome {
            controls: x,
            steps,
            status,
            iterations,
        })
    };
    if budget.met(&steps[0]) {
        return finish(x, steps, FitStatus::Met);
    }
    if method == Method::Direct {
        let x = direct_solve(problem)?;
        let mut fitted = vec![DVec3::ZERO; nrows];
        n.mul_vec3(&x, &mut fitted);
        let res: Vec<DVec3> = problem
            .data
            .iter()
            .zip(&fitted)
            .map(|(p, f)| *p - *f)
            .collect();
        steps.push(StepStats::from_residuals(
            1,
            &res,
            budget.tolerance,
            elapsed(),
        ));
        report(&steps[1]);
        let status = if budget.met(&steps[1]) || !budget.has_targets() {
            FitStatus::Met
        } else {
            FitStatus::Stalled
        };
        return finish(x, steps, status);
    }
    if method == Method::Pia && problem.pia_operator.is_none() {
        return Err(FitError::NoPiaOperator);
    }
    let mu = if method == Method::Lspia {
        let estimate = || lambda_max(problem.basis, problem.fairness, problem.smoothing, 40);
        let lambda = if problem.fairness.is_none() || problem.smoothing <= 0.0 {
            problem.basis.cached_lambda_max(estimate)
        } else {
            estimate()
        };
        1.9 / (1.02 * lambda.max(1e-300))
    } else {
        0.0
    };
    let nc = x.len();
    let mut grad = vec![DVec3::ZERO; nc];
    a.apply_t(&r_data, &r_fair, &mut grad);
    let grad0 = dot3(&grad, &grad).max_element().max(1e-300);
    let mut dir = grad.clone();
    let mut gamma = dot3(&grad, &grad);
    let mut q_data = vec![DVec3::ZERO; nrows];
    let mut q_fair = Vec::new();
    for k in 1..=budget.max_iterations {
        match method {
            Method::Cg => {
                a.apply(&dir, &mut q_data, &mut q_fair);
                let delta = dot3(&q_data, &q_data) + dot3(&q_fair, &q_fair);
                let alpha = DVec3::select(delta.cmpgt(DVec3::ZERO), gamma / delta, DVec3::ZERO);
                update(&mut x, &dir, |xi, d| *xi += alpha * d);
                update(&mut r_data, &q_data, |r, q| *r -= alpha * q);
                r_fair
                    .iter_mut()
                    .zip(&q_fair)
                    .for_each(|(r, q)| *r -= alpha * *q);
                a.apply_t(&r_data, &r_fair, &mut grad);
                let gamma_new = dot3(&grad, &grad);
                let beta = DVec3::select(gamma.cmpgt(DVec3::ZERO), gamma_new / gamma, DVec3::ZERO);
                update(&mut dir, &grad, |d, g| *d = g + beta * *d);
                gamma = gamma_new;
            }
            Method::Lspia => {
                update(&mut x, &grad, |xi, g| *xi += g * mu);
                a.residuals(&x, &mut r_data, &mut r_fair);
                a.apply_t(&r_data, &r_fair, &mut grad);
                gamma = dot3(&grad, &grad);
            }
            Method::Pia => {
                let op = problem.pia_operator.ok_or(FitError::NoPiaOperator)?;
                let delta = op(&r_data);
                x.iter_mut().zip(&delta).for_each(|(xi, d)| *xi += *d);
                a.residuals(&x, &mut r_data, &mut r_fair);
                a.apply_t(&r_data, &r_fair, &mut grad);
                gamma = dot3(&grad, &grad);
            }
            Method::Direct => unreachable!("handled above"),
        }
        let stats = StepStats::from_residuals(k, &r_data, budget.tolerance, elapsed());
        let converged = gamma.max_element() <= 1e-26 * grad0;
        report(&stats);
        steps.push(stats);
        let last = &steps[k];
        if budget.met(last) {
            return finish(x, steps, FitStatus::Met);
        }
        if converged {
            let status = if budget.has_targets() {
                FitStatus::Stalled
            } else {
                FitStatus::Met
            };
            return finish(x, steps, status);
        }
        if budget.has_targets() && budget.stalled(&steps) {
            return finish(x, steps, FitStatus::Stalled);
        }
        if time_up(last.elapsed_ms) {
            return finish(x, steps, FitStatus::Capped);
        }
    }
    let status = if budget.has_targets() {
        FitStatus::Capped
    } else {
        FitStatus::Met
    };
    finish(x, steps, status)
}

/// Sparse Cholesky (faer, fill-reducing ordering) of `N^T N + s L^T L`, assembled as the
/// scan fits assemble it (`normal_matrix`).
fn direct_solve(problem: &FitProblem) -> Result<Vec<DVec3>, FitError> {
    let fairness = problem.fairness.map(|l| Fairness {
        l: l.n(),
        lt: l.nt(),
        smoothing: problem.smoothing,
    });
    ScalarMatrix::assemble(problem.basis.n(), problem.data, fairness, true)
        .solve_direct()
        .map_err(|failure| {
            FitError::Direct(
                match failure {
                    DirectFailure::NotDefinite => "normal matrix is not positive definite: control points without data; add smoothing",
                    DirectFailure::NotFinite => "the factorisation produced non-finite values (ill-conditioned normal matrix)",
                }
                .into(),
            )
        })
}

/// Umbrella Laplacian of a control net: row i is `P_i - mean(neighbours)`.
pub fn umbrella_laplacian(control_count: usize, faces: &[[u32; 3]]) -> Csr {
    let mut nbrs: Vec<Vec<u32>> = vec![Vec::new(); control_count];
    for t in faces {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            nbrs[a as usize].push(b);
            nbrs[b as usize].push(a);
        }
    }
    let rows: Vec<Vec<(u32, f64)>> = nbrs
        .iter_mut()
        .enumerate()
        .map(|(i, nb)| {
            nb.sort_unstable();
            nb.dedup();
            if nb.is_empty() {
                return Vec::new();
            }
            let w = 1.0 / nb.len() as f64;
            std::iter::once((i as u32, 1.0))
                .chain(nb.iter().map(|&j| (j, -w)))
                .collect()
        })
        .collect();
    Csr::from_rows(control_count, rows.iter().map(|r| r.as_slice()))
}
