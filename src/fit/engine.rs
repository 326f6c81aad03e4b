//! The fitting iterations: PIA, LSPIA, CG on the normal equations (CGLS), and a direct
//! solve as ground truth. All minimise `|N P - p|^2 + s |L P|^2` (PIA only the first term).

use super::budget::{Budget, FitStatus, StepStats};
use super::collocation::Collocation;
use super::csr::Csr;
use super::normal_matrix::{Fairness, ScalarMatrix};
use super::normal_solve::DirectFailure;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// How the control points are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Progressive iterative approximation through an inverse-subdivision operator.
    Pia,
    /// Least-squares PIA: gradient steps of fixed size 1.9 / lambda_max.
    Lspia,
    /// Conjugate gradients on the normal equations (CGLS).
    Cg,
    /// Sparse Cholesky of the normal equations, in one step.
    Direct,
}

impl Method {
    /// Every method, in the order a user interface lists them.
    pub const ALL: [Method; 4] = [Method::Pia, Method::Lspia, Method::Cg, Method::Direct];

    /// The method's name in configs, output files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Pia => "pia",
            Method::Lspia => "lspia",
            Method::Cg => "cg",
            Method::Direct => "direct",
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Method {
    type Err = crate::names::UnknownName;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| crate::names::UnknownName::new(s, Method::ALL.map(Method::name)))
    }
}

/// A fit that cannot start or cannot finish.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FitError {
    /// PIA was asked for without the operator it iterates with.
    #[error("method pia needs an inverse-subdivision operator (data on the subdivision lattice)")]
    NoPiaOperator,
    /// The data do not match the collocation operator's rows (data count, rows).
    #[error("{0} data points but the collocation matrix has {1} rows")]
    Shape(usize, usize),
    /// The starting net does not match the operator's columns (given, expected).
    #[error("initial net has {0} points, the surface {1} control points")]
    InitialShape(usize, usize),
    /// The direct solve found no solution.
    #[error("direct solve: {0}")]
    Direct(#[source] DirectFailure),
}

impl FitError {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::NoPiaOperator => "no_pia_operator",
            Self::Shape(..) => "shape",
            Self::InitialShape(..) => "initial_shape",
            Self::Direct(_) => "direct_solve",
        }
    }
}

/// The paper's PIA step operator: maps data residuals to control-point corrections (the
/// inverse subdivision of the residuals); a fit's `pia` term.
pub type PiaOperator<'a> = &'a (dyn Fn(&[DVec3]) -> Vec<DVec3> + Sync);

/// A fit's inputs: the operator, the data and the optional fairness and PIA terms.
pub struct FitProblem<'a> {
    /// The collocation operator N.
    pub basis: &'a Collocation,
    /// Data points, one per row of N.
    pub data: &'a [DVec3],
    /// Weight s of the fairness term s |L P|^2 (0 = none).
    pub smoothing: f64,
    /// Fairness operator L over control points (with its transpose).
    pub fairness: Option<&'a Collocation>,
    /// PIA's update from data residuals to control corrections (method pia only).
    pub pia_operator: Option<PiaOperator<'a>>,
    /// Called with every step's statistics as soon as they exist (k = 0, the starting
    /// net, first), e.g. for a progress bar. Runs on the fitting thread between steps.
    pub on_step: Option<StepHook<'a>>,
}

/// Called with every step's statistics.
pub type StepHook<'a> = &'a (dyn Fn(&StepStats) + Sync);

#[derive(Clone, Debug)]
/// A finished fit.
pub struct FitOutcome {
    /// The fitted control points.
    pub controls: Vec<DVec3>,
    /// k = 0 is the initial net.
    pub steps: Vec<StepStats>,
    /// Why it stopped.
    pub status: FitStatus,
    /// Steps taken (`steps.len() - 1`).
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

/// Fits the control points to the data from `initial` with `method` until `budget` is met,
/// stalls or runs out (the outcome says which).
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
    let mut log = StepLog {
        problem,
        budget,
        start: Instant::now(),
        steps: Vec::new(),
    };
    let a = Stacked {
        p: problem,
        root_s: problem.smoothing.max(0.0).sqrt(),
    };
    let x = initial;
    let mut r_data = vec![DVec3::ZERO; nrows];
    let mut r_fair = Vec::new();
    a.residuals(&x, &mut r_data, &mut r_fair);
    log.record(0, &r_data);
    if budget.met(&log.steps[0]) {
        return Ok(log.finish(x, FitStatus::Met));
    }
    if method == Method::Direct {
        return direct_fit(problem, log);
    }
    if method == Method::Pia && problem.pia_operator.is_none() {
        return Err(FitError::NoPiaOperator);
    }
    let mu = if method == Method::Lspia {
        lspia_step(problem)
    } else {
        0.0
    };
    let mut state = Iterate::new(&a, x, r_data, r_fair);
    for k in 1..=budget.max_iterations {
        state.step(&a, method, mu)?;
        let converged = state.gamma.max_element() <= CONVERGED * state.grad0;
        log.record(k, &state.r_data);
        if let Some(status) = log.stop(k, converged) {
            return Ok(log.finish(state.x, status));
        }
    }
    let status = if budget.has_targets() {
        FitStatus::Capped
    } else {
        FitStatus::Met
    };
    Ok(log.finish(state.x, status))
}

/// The iteration has converged when every coordinate's squared gradient fell below this
/// fraction of its start: further steps would only move rounding noise.
const CONVERGED: f64 = 1e-26;

/// The steps so far, reported to the hook as they are recorded.
struct StepLog<'a> {
    problem: &'a FitProblem<'a>,
    budget: &'a Budget,
    start: Instant,
    steps: Vec<StepStats>,
}

impl StepLog<'_> {
    fn record(&mut self, k: usize, r_data: &[DVec3]) {
        let elapsed = self.start.elapsed().as_secs_f64() * 1e3;
        let stats = StepStats::from_residuals(k, r_data, self.budget.tolerance, elapsed);
        if let Some(hook) = self.problem.on_step {
            hook(&stats);
        }
        self.steps.push(stats);
    }

    /// Whether to stop after step `k`, and with which status.
    fn stop(&self, k: usize, converged: bool) -> Option<FitStatus> {
        let budget = self.budget;
        let last = &self.steps[k];
        if budget.met(last) {
            return Some(FitStatus::Met);
        }
        if converged {
            return Some(if budget.has_targets() {
                FitStatus::Stalled
            } else {
                FitStatus::Met
            });
        }
        if budget.has_targets() && budget.stalled(&self.steps) {
            return Some(FitStatus::Stalled);
        }
        if budget
            .max_time_ms
            .is_some_and(|m| last.elapsed_ms >= m as f64)
        {
            return Some(FitStatus::Capped);
        }
        None
    }

    fn finish(self, controls: Vec<DVec3>, status: FitStatus) -> FitOutcome {
        let iterations = self.steps.len() - 1;
        FitOutcome {
            controls,
            steps: self.steps,
            status,
            iterations,
        }
    }
}

/// One direct solve, reported as step 1.
fn direct_fit(problem: &FitProblem, mut log: StepLog) -> Result<FitOutcome, FitError> {
    let x = direct_solve(problem)?;
    let mut fitted = vec![DVec3::ZERO; problem.basis.nrows()];
    problem.basis.mul_vec3(&x, &mut fitted);
    let res: Vec<DVec3> = problem
        .data
        .iter()
        .zip(&fitted)
        .map(|(p, f)| *p - *f)
        .collect();
    log.record(1, &res);
    let budget = log.budget;
    let status = if budget.met(&log.steps[1]) || !budget.has_targets() {
        FitStatus::Met
    } else {
        FitStatus::Stalled
    };
    Ok(log.finish(x, status))
}

/// LSPIA's step size, 1.9 / lambda_max(A^T A) with 2% margin on the estimate (a step of
/// 2 / lambda_max would no longer converge). Without smoothing the estimate depends on N
/// alone and is cached on it.
fn lspia_step(problem: &FitProblem) -> f64 {
    let estimate = || lambda_max(problem.basis, problem.fairness, problem.smoothing, 40);
    let lambda = if problem.fairness.is_none() || problem.smoothing <= 0.0 {
        problem.basis.cached_lambda_max(estimate)
    } else {
        estimate()
    };
    1.9 / (1.02 * lambda.max(1e-300))
}

/// The iterate and the vectors the methods carry from step to step.
struct Iterate {
    x: Vec<DVec3>,
    r_data: Vec<DVec3>,
    r_fair: Vec<DVec3>,
    /// A^T r.
    grad: Vec<DVec3>,
    /// |A^T r|^2 per coordinate, at the start and now.
    grad0: f64,
    gamma: DVec3,
    /// CG's search direction and A dir.
    dir: Vec<DVec3>,
    q_data: Vec<DVec3>,
    q_fair: Vec<DVec3>,
}

impl Iterate {
    fn new(a: &Stacked, x: Vec<DVec3>, r_data: Vec<DVec3>, r_fair: Vec<DVec3>) -> Self {
        let nrows = r_data.len();
        let mut grad = vec![DVec3::ZERO; x.len()];
        a.apply_t(&r_data, &r_fair, &mut grad);
        let grad0 = dot3(&grad, &grad).max_element().max(1e-300);
        let dir = grad.clone();
        let gamma = dot3(&grad, &grad);
        Self {
            x,
            r_data,
            r_fair,
            grad,
            grad0,
            gamma,
            dir,
            q_data: vec![DVec3::ZERO; nrows],
            q_fair: Vec::new(),
        }
    }

    fn step(&mut self, a: &Stacked, method: Method, mu: f64) -> Result<(), FitError> {
        match method {
            Method::Cg => {
                a.apply(&self.dir, &mut self.q_data, &mut self.q_fair);
                let delta = dot3(&self.q_data, &self.q_data) + dot3(&self.q_fair, &self.q_fair);
                let gamma = self.gamma;
                let alpha = DVec3::select(delta.cmpgt(DVec3::ZERO), gamma / delta, DVec3::ZERO);
                update(&mut self.x, &self.dir, |xi, d| *xi += alpha * d);
                update(&mut self.r_data, &self.q_data, |r, q| *r -= alpha * q);
                self.r_fair
                    .iter_mut()
                    .zip(&self.q_fair)
                    .for_each(|(r, q)| *r -= alpha * *q);
                a.apply_t(&self.r_data, &self.r_fair, &mut self.grad);
                let gamma_new = dot3(&self.grad, &self.grad);
                let beta = DVec3::select(gamma.cmpgt(DVec3::ZERO), gamma_new / gamma, DVec3::ZERO);
                update(&mut self.dir, &self.grad, |d, g| *d = g + beta * *d);
                self.gamma = gamma_new;
            }
            Method::Lspia => {
                update(&mut self.x, &self.grad, |xi, g| *xi += g * mu);
                a.residuals(&self.x, &mut self.r_data, &mut self.r_fair);
                a.apply_t(&self.r_data, &self.r_fair, &mut self.grad);
                self.gamma = dot3(&self.grad, &self.grad);
            }
            Method::Pia => {
                let op = a.p.pia_operator.ok_or(FitError::NoPiaOperator)?;
                let delta = op(&self.r_data);
                self.x.iter_mut().zip(&delta).for_each(|(xi, d)| *xi += *d);
                a.residuals(&self.x, &mut self.r_data, &mut self.r_fair);
                a.apply_t(&self.r_data, &self.r_fair, &mut self.grad);
                self.gamma = dot3(&self.grad, &self.grad);
            }
            Method::Direct => unreachable!("fit hands Direct to direct_fit before iterating"),
        }
        Ok(())
    }
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
        .map_err(FitError::Direct)
}

/// Umbrella Laplacian of a control net: row i is `P_i - mean(neighbours)`.
pub fn umbrella_laplacian(control_count: usize, faces: &[[u32; 3]]) -> Csr {
    let edges = faces
        .iter()
        .flat_map(|t| (0..3).map(move |k| [t[k], t[(k + 1) % 3]]));
    umbrella_laplacian_of_edges(control_count, edges)
}

/// The umbrella Laplacian of a control mesh with crease edges: a vertex on a crease (two
/// crease edges) is compared with the mean of its two crease neighbours only, a crease
/// corner (three or more) with nothing, any other vertex with all its neighbours. The
/// fairness then straightens a crease along itself instead of pulling it towards the
/// faces on either side, which would round it off.
pub fn umbrella_laplacian_with_creases(
    control_count: usize,
    faces: &[[u32; 3]],
    creases: &[[u32; 2]],
) -> Csr {
    if creases.is_empty() {
        return umbrella_laplacian(control_count, faces);
    }
    let mut along: Vec<Vec<u32>> = vec![Vec::new(); control_count];
    for &[a, b] in creases {
        if a != b && (a as usize) < control_count && (b as usize) < control_count {
            along[a as usize].push(b);
            along[b as usize].push(a);
        }
    }
    let mut nbrs: Vec<Vec<u32>> = vec![Vec::new(); control_count];
    for t in faces {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if (a as usize) < control_count && (b as usize) < control_count {
                nbrs[a as usize].push(b);
                nbrs[b as usize].push(a);
            }
        }
    }
    let rows: Vec<Vec<(u32, f64)>> = nbrs
        .into_iter()
        .zip(along)
        .enumerate()
        .map(|(i, (mut all, mut crease))| {
            crease.sort_unstable();
            crease.dedup();
            let nb = match crease.len() {
                0 | 1 => {
                    all.sort_unstable();
                    all.dedup();
                    all
                }
                2 => crease,
                _ => Vec::new(),
            };
            umbrella_row(i as u32, &nb)
        })
        .collect();
    Csr::from_rows(control_count, rows.iter().map(|r| r.as_slice()))
}

/// Row `i` of an umbrella Laplacian: 1 at `i`, the mean over `neighbours` subtracted;
/// empty (no fairing) for a vertex without neighbours.
fn umbrella_row(i: u32, neighbours: &[u32]) -> Vec<(u32, f64)> {
    if neighbours.is_empty() {
        return Vec::new();
    }
    let w = 1.0 / neighbours.len() as f64;
    std::iter::once((i, 1.0))
        .chain(neighbours.iter().map(|&j| (j, -w)))
        .collect()
}

/// The umbrella Laplacian of a net given by its edges (either direction, repeats allowed).
pub fn umbrella_laplacian_of_edges(
    control_count: usize,
    edges: impl IntoIterator<Item = [u32; 2]>,
) -> Csr {
    let mut nbrs: Vec<Vec<u32>> = vec![Vec::new(); control_count];
    for [a, b] in edges {
        nbrs[a as usize].push(b);
        nbrs[b as usize].push(a);
    }
    let rows: Vec<Vec<(u32, f64)>> = nbrs
        .iter_mut()
        .enumerate()
        .map(|(i, nb)| {
            nb.sort_unstable();
            nb.dedup();
            umbrella_row(i as u32, nb)
        })
        .collect();
    Csr::from_rows(control_count, rows.iter().map(|r| r.as_slice()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crease_vertices_are_faired_along_their_crease_only() {
        // A fan of four faces around vertex 0; 1-0-3 is a crease, 2 and 4 are off it.
        let faces = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]];
        let plain = umbrella_laplacian(5, &faces);
        let creased = umbrella_laplacian_with_creases(5, &faces, &[[1, 0], [0, 3]]);
        let row = |m: &Csr, i: usize| -> Vec<(u32, f64)> {
            let span = m.row_ptr[i]..m.row_ptr[i + 1];
            let mut r: Vec<(u32, f64)> = m.col_idx[span.clone()]
                .iter()
                .copied()
                .zip(m.values[span].iter().copied())
                .collect();
            r.sort_by_key(|e| e.0);
            r
        };
        assert_eq!(row(&plain, 0).len(), 5);
        assert_eq!(row(&creased, 0), vec![(0, 1.0), (1, -0.5), (3, -0.5)]);
        // Vertex 2 has no crease edge: all its neighbours.
        assert_eq!(row(&creased, 2), row(&plain, 2));
        // Three crease edges at 0: a corner, not faired.
        let corner = umbrella_laplacian_with_creases(5, &faces, &[[1, 0], [0, 3], [0, 2]]);
        assert!(row(&corner, 0).is_empty());
    }

    #[test]
    fn method_names_parse_back_and_are_the_serde_names() {
        for m in Method::ALL {
            assert_eq!(m.name().parse::<Method>(), Ok(m));
            assert_eq!(serde_json::to_value(m).expect("serialises"), m.name());
        }
        let e = "gauss".parse::<Method>().expect_err("no such method");
        assert_eq!(e.expected, ["pia", "lspia", "cg", "direct"]);
    }
}
