//! Least-squares fitting of curves and grid surfaces, and the adaptive loop.
//!
//! Every fit here reduces to one banded least-squares solve (`lsq::BandedQr`) with many
//! right-hand sides: a curve is 3 of them (x, y, z); a pass over a grid is 3 per grid line,
//! because all lines of a grid share their parameters and therefore their matrix.

use super::basis::{
    approximation_knots, averaging_knots, basis_row, parameters, schoenberg_whitney, ParamMethod,
};
use super::lsq::BandedQr;
use super::{BSplineCurve, BSplineError, BSplineSurface};
use glam::DVec3;

/// How the end points are treated by a least-squares curve fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ends {
    /// First and last control points are the first and last data points (the documents').
    Interpolated,
    /// Plain least squares over every control point.
    Free,
}

/// Error summary of a fit: distances between data points and the surface (or curve) at
/// the data parameters, which bound the true point-to-surface distances from above.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    /// Largest error.
    pub max_error: f64,
    /// Root mean square error.
    pub rms_error: f64,
    /// Mean error.
    pub mean_error: f64,
}

impl ErrorStats {
    /// Statistics of a list of point errors (all zero for an empty list).
    pub fn of(errors: &[f64]) -> Self {
        if errors.is_empty() {
            return Self::default();
        }
        let n = errors.len() as f64;
        Self {
            max_error: errors.iter().copied().fold(0.0, f64::max),
            rms_error: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
            mean_error: errors.iter().sum::<f64>() / n,
        }
    }
}

/// Least squares for `nrhs` data sets sharing parameters: `data` is row-major
/// `params.len() x nrhs`; returns `count x nrhs` control values.
pub fn lsq_shared(
    params: &[f64],
    knots: &[f64],
    p: usize,
    count: usize,
    data: &[f64],
    nrhs: usize,
    ends: Ends,
) -> Result<Vec<f64>, BSplineError> {
    let m = params.len();
    if m < count {
        return Err(BSplineError::TooFewPoints {
            points: m,
            controls: count,
        });
    }
    debug_assert_eq!(data.len(), m * nrhs);
    let row_of = |k: usize| &data[k * nrhs..(k + 1) * nrhs];
    match ends {
        Ends::Free => {
            let mut qr = BandedQr::new(count, p + 1, nrhs);
            for (k, &t) in params.iter().enumerate() {
                let b = basis_row(knots, count, p, t, 0);
                qr.add_row(b.first(p), &b.d[0][..=p], row_of(k));
            }
            qr.solve()
        }
        Ends::Interpolated => {
            let mut out = vec![0.0; count * nrhs];
            out[..nrhs].copy_from_slice(row_of(0));
            out[(count - 1) * nrhs..].copy_from_slice(row_of(m - 1));
            if count <= 2 {
                return Ok(out);
            }
            let inner = count - 2;
            let mut qr = BandedQr::new(inner, p + 1, nrhs);
            let mut rhs = vec![0.0; nrhs];
            let mut coeffs = [0.0; super::basis::MAX_DEGREE + 1];
            for (k, &t) in params.iter().enumerate().take(m - 1).skip(1) {
                let b = basis_row(knots, count, p, t, 0);
                let first = b.first(p);
                rhs.copy_from_slice(row_of(k));
                let mut lo = usize::MAX;
                let mut len = 0;
                for r in 0..=p {
                    let i = first + r;
                    let w = b.d[0][r];
                    if i == 0 || i == count - 1 {
                        // Known end controls move to the right-hand side.
                        let end = &out[i * nrhs..(i + 1) * nrhs];
                        for (x, e) in rhs.iter_mut().zip(end) {
                            *x -= w * e;
                        }
                    } else {
                        lo = lo.min(i - 1);
                        coeffs[len] = w;
                        len += 1;
                    }
                }
                if len > 0 {
                    qr.add_row(lo, &coeffs[..len], &rhs);
                }
            }
            let x = qr.solve()?;
            out[nrhs..(count - 1) * nrhs].copy_from_slice(&x);
            Ok(out)
        }
    }
}

fn flatten(points: &[DVec3]) -> Vec<f64> {
    points.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

fn unflatten(x: &[f64]) -> Vec<DVec3> {
    x.chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect()
}

fn check_points(points: &[DVec3]) -> Result<(), BSplineError> {
    match points.iter().position(|p| !p.is_finite()) {
        Some(i) => Err(BSplineError::NonFinite(i)),
        None => Ok(()),
    }
}

/// A fitted curve with its data parameters and per-point errors.
#[derive(Clone, Debug)]
pub struct CurveFit {
    /// The fitted curve.
    pub curve: BSplineCurve,
    /// Parameter of every data point.
    pub params: Vec<f64>,
    /// Distance of every data point to its curve point.
    pub errors: Vec<f64>,
    /// Statistics of `errors`.
    pub stats: ErrorStats,
}

fn curve_fit(
    points: &[DVec3],
    params: Vec<f64>,
    knots: Vec<f64>,
    p: usize,
    count: usize,
    ends: Ends,
) -> Result<CurveFit, BSplineError> {
    let x = lsq_shared(&params, &knots, p, count, &flatten(points), 3, ends)?;
    let curve = BSplineCurve::new(p, knots, unflatten(&x))?;
    let errors: Vec<f64> = points
        .iter()
        .zip(&params)
        .map(|(d, &t)| (curve.point(t) - *d).length())
        .collect();
    Ok(CurveFit {
        stats: ErrorStats::of(&errors),
        curve,
        params,
        errors,
    })
}

/// Global interpolation: one control point per data point, knots by averaging.
pub fn interpolate_curve(
    points: &[DVec3],
    p: usize,
    method: ParamMethod,
) -> Result<CurveFit, BSplineError> {
    check_points(points)?;
    if p == 0 || p > super::basis::MAX_DEGREE {
        return Err(BSplineError::Degree(p));
    }
    if points.len() < p + 1 {
        return Err(BSplineError::TooFewControls {
            count: points.len(),
            degree: p,
        });
    }
    let params = parameters(points, method);
    let knots = averaging_knots(&params, p);
    curve_fit(points, params, knots, p, points.len(), Ends::Free)
}

/// Least-squares approximation by `count` control points (knots by the averaging rule for
/// approximation).
pub fn approximate_curve(
    points: &[DVec3],
    count: usize,
    p: usize,
    method: ParamMethod,
    ends: Ends,
) -> Result<CurveFit, BSplineError> {
    check_points(points)?;
    if p == 0 || p > super::basis::MAX_DEGREE {
        return Err(BSplineError::Degree(p));
    }
    if count < p + 1 {
        return Err(BSplineError::TooFewControls { count, degree: p });
    }
    let params = parameters(points, method);
    if points.len() < count {
        return Err(BSplineError::TooFewPoints {
            points: points.len(),
            controls: count,
        });
    }
    let knots = if points.len() == count {
        averaging_knots(&params, p)
    } else {
        approximation_knots(&params, count, p)
    };
    curve_fit(points, params, knots, p, count, ends)
}

/// Splits the knot span holding the largest error at the middle of the data parameters
/// inside it. Spans with fewer than two data parameters inside cannot be split without an
/// empty span; the next worst is tried. Returns false when nothing can be split.
fn insert_knot_at_worst(
    knots: &mut Vec<f64>,
    count: usize,
    p: usize,
    sorted_params: &[f64],
    span_error: &[f64],
) -> bool {
    let mut order: Vec<usize> = (0..span_error.len()).collect();
    order.sort_by(|&a, &b| span_error[b].total_cmp(&span_error[a]));
    for s in order {
        if span_error[s] <= 0.0 {
            break;
        }
        let (a, b) = (knots[s], knots[s + 1]);
        let inside: Vec<f64> = sorted_params
            .iter()
            .copied()
            .filter(|&t| t > a && t < b)
            .collect();
        if inside.len() < 2 {
            continue;
        }
        let h = inside.len() / 2;
        let t = 0.5 * (inside[h - 1] + inside[h]);
        if t <= a || t >= b {
            continue;
        }
        let mut trial = knots.clone();
        trial.insert(s + 1, t);
        if schoenberg_whitney(&trial, count + 1, p, sorted_params) {
            *knots = trial;
            return true;
        }
    }
    false
}

/// Max error per knot span (indexed by span) of points with the given parameters.
fn span_errors(knots: &[f64], count: usize, p: usize, params: &[f64], errors: &[f64]) -> Vec<f64> {
    let mut e = vec![0.0; count];
    for (&t, &err) in params.iter().zip(errors) {
        let s = super::basis::find_span(knots, count, p, t);
        e[s] = f64::max(e[s], err);
    }
    e
}

fn sorted(v: &[f64]) -> Vec<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s
}

/// The adaptive loop: start from p + 1 control points (one Bezier segment), fit, and while
/// some point is farther than `tolerance`, insert a knot in the span with the largest error
/// and fit again. Stops at `max_count` control points or when interpolating.
pub fn adaptive_curve(
    points: &[DVec3],
    p: usize,
    tolerance: f64,
    method: ParamMethod,
    max_count: usize,
) -> Result<CurveFit, BSplineError> {
    check_points(points)?;
    if p == 0 || p > super::basis::MAX_DEGREE {
        return Err(BSplineError::Degree(p));
    }
    if points.len() < p + 1 {
        return Err(BSplineError::TooFewPoints {
            points: points.len(),
            controls: p + 1,
        });
    }
    let params = parameters(points, method);
    let sp = sorted(&params);
    let mut count = p + 1;
    let mut knots = [vec![0.0; p + 1], vec![1.0; p + 1]].concat();
    let max_count = max_count.min(points.len());
    loop {
        let fit = curve_fit(
            points,
            params.clone(),
            knots.clone(),
            p,
            count,
            Ends::Interpolated,
        )?;
        if fit.stats.max_error <= tolerance || count >= max_count {
            return Ok(fit);
        }
        let se = span_errors(&knots, count, p, &params, &fit.errors);
        if !insert_knot_at_worst(&mut knots, count, p, &sp, &se) {
            return Ok(fit);
        }
        count += 1;
    }
}

/// Grid data: `rows x cols` points, row-major. Rows run along u, columns along v.
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    /// Number of rows (the u direction).
    pub rows: usize,
    /// Points per row (the v direction).
    pub cols: usize,
    /// The points, row-major: point (r, c) at `r * cols + c`.
    pub points: &'a [DVec3],
}

impl Grid<'_> {
    #[inline]
    /// Point (r, c).
    pub fn at(&self, r: usize, c: usize) -> DVec3 {
        self.points[r * self.cols + c]
    }
}

/// Which least-squares problem a grid fit solves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum GridMethod {
    /// The documents' approximation: columns then rows, each a least-squares curve fit with
    /// its end points interpolated (so the four boundary curves pass near the data edges).
    TwoPass,
    /// The exact least-squares surface over all control points at once. On a grid it
    /// separates: P = A_u^+ D (A_v^+)^T, i.e. the same two passes with free ends.
    Lsq,
}

impl GridMethod {
    /// Every method, in the order a user interface lists them.
    pub const ALL: [GridMethod; 2] = [GridMethod::TwoPass, GridMethod::Lsq];

    /// The method's name in output files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            GridMethod::TwoPass => "two-pass",
            GridMethod::Lsq => "lsq",
        }
    }
}

impl std::fmt::Display for GridMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for GridMethod {
    type Err = crate::names::UnknownName;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        GridMethod::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| crate::names::UnknownName::new(s, GridMethod::ALL.map(GridMethod::name)))
    }
}

/// Grid parameters: per direction, the average over all grid lines of their own
/// parameters (the averaged chord length of the documents when `method` is chord length).
pub fn grid_parameters(grid: &Grid, method: ParamMethod) -> (Vec<f64>, Vec<f64>) {
    let mut us = vec![0.0; grid.rows];
    let mut line = Vec::with_capacity(grid.rows.max(grid.cols));
    for c in 0..grid.cols {
        line.clear();
        line.extend((0..grid.rows).map(|r| grid.at(r, c)));
        for (u, t) in us.iter_mut().zip(parameters(&line, method)) {
            *u += t / grid.cols as f64;
        }
    }
    let mut vs = vec![0.0; grid.cols];
    for r in 0..grid.rows {
        let t = parameters(&grid.points[r * grid.cols..(r + 1) * grid.cols], method);
        for (v, t) in vs.iter_mut().zip(t) {
            *v += t / grid.rows as f64;
        }
    }
    // Averages of sequences that start at 0 and end at 1 do too, up to rounding.
    for s in [&mut us, &mut vs] {
        if let Some(l) = s.last_mut() {
            *l = 1.0;
        }
        if let Some(f) = s.first_mut() {
            *f = 0.0;
        }
    }
    (us, vs)
}

/// A fitted surface with its data parameters and per-point errors (row-major, like the data).
#[derive(Clone, Debug)]
pub struct SurfaceFit {
    /// The fitted surface.
    pub surface: BSplineSurface,
    /// (u, v) of every grid point, row-major.
    pub params: Vec<(f64, f64)>,
    /// Distance of every grid point to its surface point.
    pub errors: Vec<f64>,
    /// Statistics of `errors`.
    pub stats: ErrorStats,
}

/// Fits a grid with given parameters and knots: the column pass, then the row pass.
pub(crate) fn fit_grid_with(
    grid: &Grid,
    (us, vs): (&[f64], &[f64]),
    (knots_u, knots_v): (Vec<f64>, Vec<f64>),
    (p, q): (usize, usize),
    method: GridMethod,
) -> Result<BSplineSurface, BSplineError> {
    check_points(grid.points)?;
    let cu = knots_u.len() - p - 1;
    let cv = knots_v.len() - q - 1;
    let ends = match method {
        GridMethod::TwoPass => Ends::Interpolated,
        GridMethod::Lsq => Ends::Free,
    };
    // Pass 1: every grid column (rows points) -> cu intermediate points, all at once.
    let data1 = flatten(grid.points);
    let mid = lsq_shared(us, &knots_u, p, cu, &data1, 3 * grid.cols, ends)?;
    // mid is cu x (cols x 3): intermediate point (i, c). Pass 2 runs along c.
    let mut data2 = vec![0.0; grid.cols * cu * 3];
    for i in 0..cu {
        for c in 0..grid.cols {
            for k in 0..3 {
                data2[(c * cu + i) * 3 + k] = mid[(i * grid.cols + c) * 3 + k];
            }
        }
    }
    let ctrl = lsq_shared(vs, &knots_v, q, cv, &data2, 3 * cu, ends)?;
    // ctrl is cv x (cu x 3): control (i, j) at row j.
    let mut controls = vec![DVec3::ZERO; cu * cv];
    for j in 0..cv {
        for i in 0..cu {
            let b = (j * cu + i) * 3;
            controls[i * cv + j] = DVec3::new(ctrl[b], ctrl[b + 1], ctrl[b + 2]);
        }
    }
    BSplineSurface::new((p, q), knots_u, knots_v, (cu, cv), controls)
}

/// Distances between the data and the surface at the grid parameters, row-major.
pub(crate) fn grid_errors(
    surface: &BSplineSurface,
    grid: &Grid,
    us: &[f64],
    vs: &[f64],
) -> Vec<f64> {
    let rows_v: Vec<_> = vs.iter().map(|&v| surface.row_v(v, 0)).collect();
    let mut e = Vec::with_capacity(grid.points.len());
    for (r, &u) in us.iter().enumerate() {
        let ru = surface.row_u(u, 0);
        for (c, rv) in rows_v.iter().enumerate() {
            e.push((surface.point_from_rows(&ru, rv) - grid.at(r, c)).length());
        }
    }
    e
}

fn surface_fit(grid: &Grid, us: &[f64], vs: &[f64], surface: BSplineSurface) -> SurfaceFit {
    let errors = grid_errors(&surface, grid, us, vs);
    let params = us
        .iter()
        .flat_map(|&u| vs.iter().map(move |&v| (u, v)))
        .collect();
    SurfaceFit {
        stats: ErrorStats::of(&errors),
        surface,
        params,
        errors,
    }
}

fn check_grid(
    grid: &Grid,
    (cu, cv): (usize, usize),
    (p, q): (usize, usize),
) -> Result<(), BSplineError> {
    for d in [p, q] {
        if d == 0 || d > super::basis::MAX_DEGREE {
            return Err(BSplineError::Degree(d));
        }
    }
    if cu < p + 1 || cv < q + 1 {
        let (count, degree) = if cu < p + 1 { (cu, p) } else { (cv, q) };
        return Err(BSplineError::TooFewControls { count, degree });
    }
    if grid.rows < cu || grid.cols < cv || grid.points.len() != grid.rows * grid.cols {
        return Err(BSplineError::TooFewPoints {
            points: grid.points.len(),
            controls: cu * cv,
        });
    }
    Ok(())
}

fn knots_for(params: &[f64], count: usize, p: usize) -> Vec<f64> {
    if params.len() == count {
        averaging_knots(params, p)
    } else {
        approximation_knots(params, count, p)
    }
}

/// Fits `counts` = (cu, cv) control points of degrees (p, q) to a grid. With counts equal
/// to the grid size this is global interpolation.
pub fn fit_grid(
    grid: &Grid,
    counts: (usize, usize),
    degrees: (usize, usize),
    param: ParamMethod,
    method: GridMethod,
) -> Result<SurfaceFit, BSplineError> {
    check_grid(grid, counts, degrees)?;
    let (us, vs) = grid_parameters(grid, param);
    let knots = (
        knots_for(&us, counts.0, degrees.0),
        knots_for(&vs, counts.1, degrees.1),
    );
    let s = fit_grid_with(grid, (&us, &vs), knots, degrees, method)?;
    Ok(surface_fit(grid, &us, &vs, s))
}

/// Global interpolation of a grid (the documents' (m+1) + (n+1) curve interpolations).
pub fn interpolate_grid(
    grid: &Grid,
    degrees: (usize, usize),
    param: ParamMethod,
) -> Result<SurfaceFit, BSplineError> {
    fit_grid(
        grid,
        (grid.rows, grid.cols),
        degrees,
        param,
        GridMethod::Lsq,
    )
}

/// Adaptive grid fit: from (p + 1) x (q + 1) control points, insert one knot per round
/// where the error is largest, in u or in v, whichever lowers the maximum error more
/// (both are tried: a grid fit costs microseconds), until `tolerance` or `max_counts`.
pub fn adaptive_grid(
    grid: &Grid,
    degrees: (usize, usize),
    tolerance: f64,
    param: ParamMethod,
    method: GridMethod,
    max_counts: (usize, usize),
) -> Result<SurfaceFit, BSplineError> {
    let (p, q) = degrees;
    check_grid(grid, (p + 1, q + 1), degrees)?;
    let max_u = max_counts.0.min(grid.rows);
    let max_v = max_counts.1.min(grid.cols);
    let (us, vs) = grid_parameters(grid, param);
    let (su, sv) = (sorted(&us), sorted(&vs));
    let clamped = |p: usize| [vec![0.0; p + 1], vec![1.0; p + 1]].concat();
    let fit = |ku: &Vec<f64>, kv: &Vec<f64>| -> Result<SurfaceFit, BSplineError> {
        let s = fit_grid_with(grid, (&us, &vs), (ku.clone(), kv.clone()), degrees, method)?;
        Ok(surface_fit(grid, &us, &vs, s))
    };
    let (mut ku, mut kv) = (clamped(p), clamped(q));
    let mut best = fit(&ku, &kv)?;
    while best.stats.max_error > tolerance {
        let (cu, cv) = best.surface.counts();
        // Per-span maxima of the error along each direction.
        let eu: Vec<f64> = (0..grid.rows)
            .map(|r| {
                (0..grid.cols)
                    .map(|c| best.errors[r * grid.cols + c])
                    .fold(0.0, f64::max)
            })
            .collect();
        let ev: Vec<f64> = (0..grid.cols)
            .map(|c| {
                (0..grid.rows)
                    .map(|r| best.errors[r * grid.cols + c])
                    .fold(0.0, f64::max)
            })
            .collect();
        let mut candidates = Vec::new();
        let mut try_u = ku.clone();
        if cu < max_u
            && insert_knot_at_worst(&mut try_u, cu, p, &su, &span_errors(&ku, cu, p, &us, &eu))
        {
            candidates.push((try_u, kv.clone()));
        }
        let mut try_v = kv.clone();
        if cv < max_v
            && insert_knot_at_worst(&mut try_v, cv, q, &sv, &span_errors(&kv, cv, q, &vs, &ev))
        {
            candidates.push((ku.clone(), try_v));
        }
        let mut next: Option<(SurfaceFit, Vec<f64>, Vec<f64>)> = None;
        for (a, b) in candidates {
            let f = fit(&a, &b)?;
            if next
                .as_ref()
                .is_none_or(|(n, _, _)| f.stats.max_error < n.stats.max_error)
            {
                next = Some((f, a, b));
            }
        }
        match next {
            Some((f, a, b)) => {
                best = f;
                ku = a;
                kv = b;
            }
            None => break,
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_method_names_parse_back_and_are_the_serde_names() {
        for m in GridMethod::ALL {
            assert_eq!(m.name().parse::<GridMethod>(), Ok(m));
            assert_eq!(serde_json::to_value(m).expect("serialises"), m.name());
        }
        assert!("two_pass".parse::<GridMethod>().is_err());
    }
}
