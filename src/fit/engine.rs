//! The fitting iterations: PIA, LSPIA, CG on the normal equations (CGLS), and a direct
//! solve as ground truth. All minimise `|N P - p|^2 + s |L P|^2` (PIA only the first term).

use super::budget::{Budget, FitStatus, StepStats};
use super::sparse::{Collocation, Csr};
use glam::DVec3;
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
}

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
        self.p.basis.n.mul_vec3(x, data_part);
        if let Some(l) = self.fair() {
            fair_part.resize(l.n.nrows, DVec3::ZERO);
            l.n.mul_vec3(x, fair_part);
            fair_part.iter_mut().for_each(|v| *v *= self.root_s);
        }
    }
    /// Residuals of the stacked system at x: data part p - N x, fairness part -sqrt(s) L x.
    fn residuals(&self, x: &[DVec3], data_part: &mut [DVec3], fair_part: &mut Vec<DVec3>) {
        self.apply(x, data_part, fair_part);
        data_part
            .iter_mut()
            .zip(self.p.data)
            .for_each(|(r, p)| *r = *p - *r);
        fair_part.iter_mut().for_each(|v| *v = -*v);
    }

    fn apply_t(&self, data_part: &[DVec3], fair_part: &[DVec3], out: &mut [DVec3]) {
        self.p.basis.nt.mul_vec3(data_part, out);
        if let Some(l) = self.fair() {
            let mut tmp = vec![DVec3::ZERO; out.len()];
            l.nt.mul_vec3(fair_part, &mut tmp);
            out.iter_mut()
                .zip(&tmp)
                .for_each(|(o, t)| *o += *t * self.root_s);
        }
    }
}

fn dot3(a: &[DVec3], b: &[DVec3]) -> DVec3 {
    a.iter().zip(b).map(|(x, y)| *x * *y).sum()
}

/// Largest eigenvalue of A^T A by power iteration from the all-ones vector, which for a
/// non-negative N has a large component along the Perron vector.
pub fn lambda_max(
    basis: &Collocation,
    fairness: Option<&Collocation>,
    smoothing: f64,
    iterations: usize,
) -> f64 {
    let nc = basis.n.ncols;
    let mut x = vec![1.0 / (nc as f64).sqrt(); nc];
    let mut lambda = 0.0;
    let scalar = |m: &Csr, x: &[f64]| -> Vec<f64> {
        (0..m.nrows)
            .map(|r| {
                (m.row_ptr[r]..m.row_ptr[r + 1])
                    .map(|k| m.values[k] * x[m.col_idx[k] as usize])
                    .sum()
            })
            .collect()
    };
    for _ in 0..iterations {
        let nx = scalar(&basis.n, &x);
        let mut y = scalar(&basis.nt, &nx);
        if let Some(l) = fairness.filter(|_| smoothing > 0.0) {
            let lx = scalar(&l.n, &x);
            let lt = scalar(&l.nt, &lx);
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
    let n = &problem.basis.n;
    if problem.data.len() != n.nrows {
        return Err(FitError::Shape(problem.data.len(), n.nrows));
    }
    if initial.len() != n.ncols {
        return Err(FitError::InitialShape(initial.len(), n.ncols));
    }
    let start = Instant::now();
    let elapsed = || start.elapsed().as_secs_f64() * 1e3;
    let a = Stacked {
        p: problem,
        root_s: problem.smoothing.max(0.0).sqrt(),
    };
    let mut x = initial;
    let mut r_data = vec![DVec3::ZERO; n.nrows];
    let mut r_fair = Vec::new();
    a.residuals(&x, &mut r_data, &mut r_fair);
    let mut steps = vec![StepStats::from_residuals(
        0,
        &r_data,
        budget.tolerance,
        elapsed(),
    )];
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
        let mut fitted = vec![DVec3::ZERO; n.nrows];
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
        let lambda = lambda_max(problem.basis, problem.fairness, problem.smoothing, 40);
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
    let mut q_data = vec![DVec3::ZERO; n.nrows];
    let mut q_fair = Vec::new();
    for k in 1..=budget.max_iterations {
        match method {
            Method::Cg => {
                a.apply(&dir, &mut q_data, &mut q_fair);
                let delta = dot3(&q_data, &q_data) + dot3(&q_fair, &q_fair);
                let alpha = DVec3::select(delta.cmpgt(DVec3::ZERO), gamma / delta, DVec3::ZERO);
                x.iter_mut().zip(&dir).for_each(|(xi, d)| *xi += alpha * *d);
                r_data
                    .iter_mut()
                    .zip(&q_data)
                    .for_each(|(r, q)| *r -= alpha * *q);
                r_fair
                    .iter_mut()
                    .zip(&q_fair)
                    .for_each(|(r, q)| *r -= alpha * *q);
                a.apply_t(&r_data, &r_fair, &mut grad);
                let gamma_new = dot3(&grad, &grad);
                let beta = DVec3::select(gamma.cmpgt(DVec3::ZERO), gamma_new / gamma, DVec3::ZERO);
                dir.iter_mut()
                    .zip(&grad)
                    .for_each(|(d, g)| *d = *g + beta * *d);
                gamma = gamma_new;
            }
            Method::Lspia => {
                x.iter_mut().zip(&grad).for_each(|(xi, g)| *xi += *g * mu);
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

/// Dense Cholesky of the normal equations. Used as ground truth and for small nets; a
/// sparse factorisation is needed beyond a few thousand control points.
pub const DIRECT_MAX_CONTROLS: usize = 6000;

fn direct_solve(problem: &FitProblem) -> Result<Vec<DVec3>, FitError> {
    let n = &problem.basis.n;
    let nc = n.ncols;
    if nc > DIRECT_MAX_CONTROLS {
        return Err(FitError::Direct(format!(
            "{nc} control points; the dense solve takes at most {DIRECT_MAX_CONTROLS}"
        )));
    }
    let mut m = nalgebra::DMatrix::<f64>::zeros(nc, nc);
    let mut rhs = nalgebra::DMatrix::<f64>::zeros(nc, 3);
    let mut accumulate = |csr: &Csr, scale: f64, data: Option<&[DVec3]>| {
        for r in 0..csr.nrows {
            let range = csr.row_ptr[r]..csr.row_ptr[r + 1];
            for a in range.clone() {
                let (ca, wa) = (csr.col_idx[a] as usize, csr.values[a]);
                for b in range.clone() {
                    m[(ca, csr.col_idx[b] as usize)] += scale * wa * csr.values[b];
                }
                if let Some(d) = data {
                    let p = d[r];
                    for (k, c) in [p.x, p.y, p.z].into_iter().enumerate() {
                        rhs[(ca, k)] += wa * c;
                    }
                }
            }
        }
    };
    accumulate(n, 1.0, Some(problem.data));
    if let Some(l) = problem.fairness.filter(|_| problem.smoothing > 0.0) {
        accumulate(&l.n, problem.smoothing, None);
    }
    let chol = nalgebra::Cholesky::new(m).ok_or_else(|| {
        FitError::Direct(
            "normal matrix is singular: control points without data; add smoothing".into(),
        )
    })?;
    let sol = chol.solve(&rhs);
    Ok((0..nc)
        .map(|i| DVec3::new(sol[(i, 0)], sol[(i, 1)], sol[(i, 2)]))
        .collect())
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
