//! Tensor-product fits of scattered points (no grid): parameters by projection onto the
//! best-fit plane, the full least-squares problem over all control points with optional
//! thin-plate-like smoothing, LSPIA as the iterative alternative, parameter correction by
//! foot-point projection, and the adaptive control count.

use super::basis::{approximation_knots, basis_row, schoenberg_whitney, MAX_DEGREE};
use super::fit::ErrorStats;
use super::lsq::BandedQr;
use super::{BSplineError, BSplineSurface};
use glam::DVec3;

/// Parameters in [0, 1]^2 from the orthogonal projection onto the least-squares plane of
/// the points (principal axes of their covariance), u along the longest axis.
pub fn planar_parameters(points: &[DVec3]) -> Vec<(f64, f64)> {
    if points.is_empty() {
        return Vec::new();
    }
    let c = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let (_, axes) = crate::numeric::principal_axes(c, points.iter().copied());
    let (e1, e2) = (axes[0], axes[1]);
    let raw: Vec<(f64, f64)> = points
        .iter()
        .map(|p| ((*p - c).dot(e1), (*p - c).dot(e2)))
        .collect();
    let range = |f: fn(&(f64, f64)) -> f64| {
        raw.iter()
            .map(f)
            .fold((f64::MAX, f64::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)))
    };
    let (u0, u1) = range(|p| p.0);
    let (v0, v1) = range(|p| p.1);
    let nu = |x: f64, lo: f64, hi: f64| if hi > lo { (x - lo) / (hi - lo) } else { 0.5 };
    raw.iter()
        .map(|&(u, v)| (nu(u, u0, u1), nu(v, v0, v1)))
        .collect()
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "lowercase", tag = "solver")]
/// How the scattered least-squares system is solved.
pub enum ScatteredSolver {
    /// Banded QR of the whole system (exact least squares).
    Direct,
    /// Least-squares progressive iterative approximation from the direct fit's knots,
    /// started at the plane through the data.
    Lspia {
        /// LSPIA steps.
        iterations: usize,
    },
}

#[derive(Clone, Copy, Debug)]
/// What a scattered fit asks for.
pub struct ScatteredOptions {
    /// Control points along u and v.
    pub counts: (usize, usize),
    /// Degrees along u and v.
    pub degrees: (usize, usize),
    /// Weight of the second-difference energy of the control net, relative to the data:
    /// the penalty rows are scaled by sqrt(smoothing * data points / control points) so a
    /// value means the same balance at any density. 0 = none. Direct solver only: LSPIA
    /// iterates on the data alone.
    pub smoothing: f64,
    /// The solver.
    pub solver: ScatteredSolver,
    /// Rounds of foot-point projection of every point followed by a refit.
    pub parameter_correction: usize,
}

#[derive(Clone, Debug)]
/// A scattered fit: the surface and how far each point is from it.
pub struct ScatteredFit {
    /// The fitted surface.
    pub surface: BSplineSurface,
    /// (u, v) of every data point after the last parameter correction.
    pub params: Vec<(f64, f64)>,
    /// Distance of every data point to its surface point.
    pub errors: Vec<f64>,
    /// Statistics of `errors`.
    pub stats: ErrorStats,
}

fn check(
    points: &[DVec3],
    params: &[(f64, f64)],
    o: &ScatteredOptions,
) -> Result<(), BSplineError> {
    let (p, q) = o.degrees;
    for d in [p, q] {
        if d == 0 || d > MAX_DEGREE {
            return Err(BSplineError::Degree(d));
        }
    }
    let (cu, cv) = o.counts;
    if cu < p + 1 || cv < q + 1 {
        let (count, degree) = if cu < p + 1 { (cu, p) } else { (cv, q) };
        return Err(BSplineError::TooFewControls { count, degree });
    }
    if let Some(i) = points.iter().position(|x| !x.is_finite()) {
        return Err(BSplineError::NonFinite(i));
    }
    if let Some(i) = params
        .iter()
        .position(|x| !(x.0.is_finite() && x.1.is_finite()))
    {
        return Err(BSplineError::NonFinite(i));
    }
    if points.len() < cu * cv && o.smoothing <= 0.0 {
        return Err(BSplineError::TooFewPoints {
            points: points.len(),
            controls: cu * cv,
        });
    }
    Ok(())
}

/// Knots at quantiles of the data parameters (the approximation averaging rule applied to
/// the sorted parameters), so denser data gets more knots.
pub(crate) fn scattered_knots(
    params: &[(f64, f64)],
    (cu, cv): (usize, usize),
    (p, q): (usize, usize),
) -> (Vec<f64>, Vec<f64>) {
    let mut us: Vec<f64> = params.iter().map(|x| x.0).collect();
    let mut vs: Vec<f64> = params.iter().map(|x| x.1).collect();
    us.sort_by(f64::total_cmp);
    vs.sort_by(f64::total_cmp);
    let k = |s: &[f64], c: usize, d: usize| {
        if s.len() > c {
            approximation_knots(s, c, d)
        } else {
            // Too few points for quantiles (smoothing carries the rest): uniform knots.
            let mut k = vec![0.0; d + 1];
            k.extend((1..c - d).map(|j| j as f64 / (c - d) as f64));
            k.extend(std::iter::repeat_n(1.0, d + 1));
            k
        }
    };
    (k(&us, cu, p), k(&vs, cv, q))
}

/// Direct least squares with given knots.
pub(crate) fn solve_direct(
    points: &[DVec3],
    params: &[(f64, f64)],
    knots: (&[f64], &[f64]),
    o: &ScatteredOptions,
) -> Result<BSplineSurface, BSplineError> {
    let (p, q) = o.degrees;
    let (cu, cv) = o.counts;
    let n = cu * cv;
    // A data row touches (p + 1) rows of q + 1 consecutive controls: its span in the
    // row-major numbering is p * cv + q + 1; a second difference along u spans 2 cv + 1.
    let width = (p * cv + q + 1).max(if o.smoothing > 0.0 { 2 * cv + 1 } else { 0 });
    let mut qr = BandedQr::new(n, width, 3);
    let mut coeffs = vec![0.0; p * cv + q + 1];
    // Sorting rows by their first unknown keeps the fill of the Givens sweep local.
    let mut rows: Vec<(usize, usize, super::basis::BasisRow, super::basis::BasisRow)> = params
        .iter()
        .enumerate()
        .map(|(k, &(u, v))| {
            let ru = basis_row(knots.0, cu, p, u, 0);
            let rv = basis_row(knots.1, cv, q, v, 0);
            (ru.first(p) * cv + rv.first(q), k, ru, rv)
        })
        .collect();
    rows.sort_by_key(|r| (r.0, r.1));
    for (first, k, ru, rv) in &rows {
        coeffs.iter_mut().for_each(|c| *c = 0.0);
        for a in 0..=p {
            for b in 0..=q {
                coeffs[a * cv + b] = ru.d[0][a] * rv.d[0][b];
            }
        }
        let d = points[*k];
        qr.add_row(*first, &coeffs, &[d.x, d.y, d.z]);
    }
    if o.smoothing > 0.0 {
        let w = (o.smoothing * points.len() as f64 / n as f64).sqrt();
        let id = |i: usize, j: usize| i * cv + j;
        let mut row = vec![0.0; width];
        let mut push = |qr: &mut BandedQr, entries: &[(usize, f64)]| {
            let first = entries.iter().map(|e| e.0).min().unwrap_or(0);
            let last = entries.iter().map(|e| e.0).max().unwrap_or(0);
            row.iter_mut().for_each(|c| *c = 0.0);
            for &(i, c) in entries {
                row[i - first] += c * w;
            }
            qr.add_row(first, &row[..=last - first], &[0.0; 3]);
        };
        for i in 0..cu {
            for j in 0..cv {
                if i + 2 < cu {
                    push(
                        &mut qr,
                        &[(id(i, j), 1.0), (id(i + 1, j), -2.0), (id(i + 2, j), 1.0)],
                    );
                }
                if j + 2 < cv {
                    push(
                        &mut qr,
                        &[(id(i, j), 1.0), (id(i, j + 1), -2.0), (id(i, j + 2), 1.0)],
                    );
                }
                if i + 1 < cu && j + 1 < cv {
                    let s = std::f64::consts::SQRT_2;
                    push(
                        &mut qr,
                        &[
                            (id(i, j), s),
                            (id(i, j + 1), -s),
                            (id(i + 1, j), -s),
                            (id(i + 1, j + 1), s),
                        ],
                    );
                }
            }
        }
    }
    let x = qr.solve()?;
    let controls = x
        .chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect();
    BSplineSurface::new(
        o.degrees,
        knots.0.to_vec(),
        knots.1.to_vec(),
        o.counts,
        controls,
    )
}

/// LSPIA: P <- P + mu N^T (D - N P) with mu = 1 / max column sum of N, which is below
/// 2 / lambda_max(N^T N) because rows of N sum to 1. Converges to the least-squares
/// solution when N has full rank, more slowly than the direct solve but in O(data) memory.
pub(crate) fn solve_lspia(
    points: &[DVec3],
    params: &[(f64, f64)],
    start: BSplineSurface,
    iterations: usize,
) -> Result<BSplineSurface, BSplineError> {
    let (p, q) = start.degrees();
    let (cu, cv) = start.counts();
    let rows: Vec<_> = params
        .iter()
        .map(|&(u, v)| (start.row_u(u, 0), start.row_v(v, 0)))
        .collect();
    let mut colsum = vec![0.0; cu * cv];
    for (ru, rv) in &rows {
        for a in 0..=p {
            for b in 0..=q {
                colsum[(ru.first(p) + a) * cv + rv.first(q) + b] += ru.d[0][a] * rv.d[0][b];
            }
        }
    }
    let mu = 1.0 / colsum.iter().copied().fold(0.0, f64::max).max(1e-300);
    let mut ctrl = start.controls().to_vec();
    let mut delta = vec![DVec3::ZERO; cu * cv];
    let mut s = start;
    for _ in 0..iterations {
        delta.iter_mut().for_each(|d| *d = DVec3::ZERO);
        for ((ru, rv), d) in rows.iter().zip(points) {
            let r = *d - s.point_from_rows(ru, rv);
            for a in 0..=p {
                for b in 0..=q {
                    delta[(ru.first(p) + a) * cv + rv.first(q) + b] +=
                        r * (ru.d[0][a] * rv.d[0][b]);
                }
            }
        }
        for (c, d) in ctrl.iter_mut().zip(&delta) {
            *c += *d * mu;
        }
        s = BSplineSurface::new(
            (p, q),
            s.knots_u().to_vec(),
            s.knots_v().to_vec(),
            (cu, cv),
            ctrl.clone(),
        )?;
    }
    Ok(s)
}

fn errors_of(s: &BSplineSurface, points: &[DVec3], params: &[(f64, f64)]) -> Vec<f64> {
    points
        .iter()
        .zip(params)
        .map(|(d, &(u, v))| (s.point(u, v) - *d).length())
        .collect()
}

fn fit_with_knots(
    points: &[DVec3],
    params: &[(f64, f64)],
    ku: &[f64],
    kv: &[f64],
    o: &ScatteredOptions,
) -> Result<ScatteredFit, BSplineError> {
    let mut params = params.to_vec();
    let mut surface = fit_once(points, &params, ku, kv, o)?;
    for _ in 0..o.parameter_correction {
        for (d, t) in points.iter().zip(params.iter_mut()) {
            *t = surface.closest_point(*d, *t).0;
        }
        surface = fit_once(points, &params, ku, kv, o)?;
    }
    let errors = errors_of(&surface, points, &params);
    Ok(ScatteredFit {
        stats: ErrorStats::of(&errors),
        surface,
        params,
        errors,
    })
}

fn fit_once(
    points: &[DVec3],
    params: &[(f64, f64)],
    ku: &[f64],
    kv: &[f64],
    o: &ScatteredOptions,
) -> Result<BSplineSurface, BSplineError> {
    match o.solver {
        ScatteredSolver::Direct => solve_direct(points, params, (ku, kv), o),
        ScatteredSolver::Lspia { iterations } => {
            let start = affine_start(points, params, ku, kv, o)?;
            solve_lspia(points, params, start, iterations)
        }
    }
}

/// The least-squares affine map (u, v) -> x as a B-spline: controls at the Greville
/// abscissae reproduce it exactly. LSPIA then only has the non-affine part to converge on.
fn affine_start(
    points: &[DVec3],
    params: &[(f64, f64)],
    ku: &[f64],
    kv: &[f64],
    o: &ScatteredOptions,
) -> Result<BSplineSurface, BSplineError> {
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Matrix3::<f64>::zeros();
    for (d, &(u, v)) in points.iter().zip(params) {
        let a = nalgebra::Vector3::new(1.0, u, v);
        ata += a * a.transpose();
        atb += a * nalgebra::RowVector3::new(d.x, d.y, d.z);
    }
    // 3 x 3 and well conditioned for parameters spread over the unit square.
    let m = ata
        .cholesky()
        .map(|c| c.solve(&atb))
        .ok_or(BSplineError::RankDeficient(0))?;
    let row = |k: usize| DVec3::new(m[(k, 0)], m[(k, 1)], m[(k, 2)]);
    let (c0, cu_, cv_) = (row(0), row(1), row(2));
    let greville = |k: &[f64], d: usize, i: usize| k[i + 1..=i + d].iter().sum::<f64>() / d as f64;
    let (p, q) = o.degrees;
    let (nu, nv) = o.counts;
    let controls = (0..nu * nv)
        .map(|k| c0 + cu_ * greville(ku, p, k / nv) + cv_ * greville(kv, q, k % nv))
        .collect();
    BSplineSurface::new(o.degrees, ku.to_vec(), kv.to_vec(), o.counts, controls)
}

/// Fits scattered points with given parameters.
pub fn fit_scattered(
    points: &[DVec3],
    params: &[(f64, f64)],
    o: &ScatteredOptions,
) -> Result<ScatteredFit, BSplineError> {
    check(points, params, o)?;
    let (ku, kv) = scattered_knots(params, o.counts, o.degrees);
    fit_with_knots(points, params, &ku, &kv, o)
}

/// Adaptive control count for scattered data: from (p + 1) x (q + 1), split the knot span
/// (in u or v, whichever fit is better) holding the largest error at the median parameter
/// inside it, until `tolerance` or `max_counts`.
pub fn adaptive_scattered(
    points: &[DVec3],
    params: &[(f64, f64)],
    o: &ScatteredOptions,
    tolerance: f64,
) -> Result<ScatteredFit, BSplineError> {
    let (p, q) = o.degrees;
    let max = o.counts;
    let mut o = *o;
    o.counts = (p + 1, q + 1);
    check(points, params, &o)?;
    let mut ku = [vec![0.0; p + 1], vec![1.0; p + 1]].concat();
    let mut kv = [vec![0.0; q + 1], vec![1.0; q + 1]].concat();
    let mut best = fit_with_knots(points, params, &ku, &kv, &o)?;
    let mut su: Vec<f64> = params.iter().map(|x| x.0).collect();
    let mut sv: Vec<f64> = params.iter().map(|x| x.1).collect();
    su.sort_by(f64::total_cmp);
    sv.sort_by(f64::total_cmp);
    while best.stats.max_error > tolerance {
        let (cu, cv) = o.counts;
        let worst = best
            .errors
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|x| x.0)
            .unwrap_or(0);
        let (wu, wv) = best.params[worst];
        let mut tries = Vec::new();
        if cu < max.0 {
            if let Some(k) = split_span(&ku, cu, p, &su, wu) {
                tries.push((k, kv.clone(), (cu + 1, cv)));
            }
        }
        if cv < max.1 {
            if let Some(k) = split_span(&kv, cv, q, &sv, wv) {
                tries.push((ku.clone(), k, (cu, cv + 1)));
            }
        }
        let mut next: Option<Candidate> = None;
        for (a, b, counts) in tries {
            let mut oo = o;
            oo.counts = counts;
            let Ok(f) = fit_with_knots(points, params, &a, &b, &oo) else {
                continue;
            };
            if next
                .as_ref()
                .is_none_or(|n| f.stats.max_error < n.0.stats.max_error)
            {
                next = Some((f, a, b, counts));
            }
        }
        let Some((f, a, b, counts)) = next else { break };
        best = f;
        ku = a;
        kv = b;
        o.counts = counts;
    }
    Ok(best)
}

/// A trial of the adaptive loop: its fit, knots in u and v, control counts.
type Candidate = (ScatteredFit, Vec<f64>, Vec<f64>, (usize, usize));

/// The knot vector with the span holding `t` split at the median data parameter inside it,
/// if that leaves every basis function some data.
fn split_span(knots: &[f64], count: usize, p: usize, sorted: &[f64], t: f64) -> Option<Vec<f64>> {
    let s = super::basis::find_span(knots, count, p, t);
    let (a, b) = (knots[s], knots[s + 1]);
    let lo = sorted.partition_point(|&x| x <= a);
    let hi = sorted.partition_point(|&x| x < b);
    if hi <= lo + 1 {
        return None;
    }
    let m = (lo + hi) / 2;
    let k = 0.5 * (sorted[m - 1] + sorted[m]);
    if k <= a || k >= b {
        return None;
    }
    let mut out = knots.to_vec();
    out.insert(s + 1, k);
    schoenberg_whitney(&out, count + 1, p, sorted).then_some(out)
}
