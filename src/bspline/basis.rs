//! B-spline basis functions on clamped knot vectors, parameters and knot placement.
//!
//! Values and derivatives come from the triangular Cox-de Boor table (only the p + 1
//! functions that are non-zero on a span are ever formed), so a basis row costs O(p^2)
//! and no 0/0 quotient is ever evaluated.

use super::error::BSplineError;
pub use super::error::MAX_DEGREE;
use glam::DVec3;

const W: usize = MAX_DEGREE + 1;

/// The basis functions N_{span-p..=span, p} and their derivatives up to order 2 at one
/// parameter: `d[k][r]` is the k-th derivative of N_{span-p+r}.
#[derive(Clone, Copy, Debug)]
pub struct BasisRow {
    /// The knot span s: the row's values belong to controls s - p ..= s.
    pub span: usize,
    /// Basis values and their first and second derivatives, p + 1 each.
    pub d: [[f64; W]; 3],
}

impl BasisRow {
    /// Index of the first control point the row touches.
    #[inline]
    pub fn first(&self, degree: usize) -> usize {
        self.span - degree
    }
}

/// Checks a knot vector for `count` control points of degree `p`: length, order, clamping
/// and a non-empty domain.
pub(crate) fn validate_knots(knots: &[f64], count: usize, p: usize) -> Result<(), BSplineError> {
    if p == 0 || p > MAX_DEGREE {
        return Err(BSplineError::Degree(p));
    }
    if count < p + 1 {
        return Err(BSplineError::TooFewControls { count, degree: p });
    }
    if count.checked_add(p + 1) != Some(knots.len()) {
        return Err(BSplineError::KnotCount {
            knots: knots.len(),
            count,
            degree: p,
        });
    }
    if knots.iter().any(|k| !k.is_finite()) || knots.windows(2).any(|w| w[1] < w[0]) {
        return Err(BSplineError::KnotOrder);
    }
    let (a, b) = (knots[p], knots[count]);
    if b <= a {
        return Err(BSplineError::EmptyDomain);
    }
    // Interior multiplicity above p would disconnect the curve.
    let mut run = 1;
    for w in knots[1..knots.len() - 1].windows(2) {
        run = if w[1] == w[0] { run + 1 } else { 1 };
        if run > p && w[0] > a && w[0] < b {
            return Err(BSplineError::KnotMultiplicity {
                knot: w[0],
                degree: p,
            });
        }
    }
    Ok(())
}

/// The span index s with knots[s] <= t < knots[s + 1], p <= s < count; the domain's right
/// end belongs to the last non-empty span. Parameters outside the domain are clamped.
pub(crate) fn find_span(knots: &[f64], count: usize, p: usize, t: f64) -> usize {
    if t >= knots[count] {
        // Last span with a positive length.
        let mut s = count - 1;
        while s > p && knots[s] >= knots[count] {
            s -= 1;
        }
        return s;
    }
    if t <= knots[p] {
        let mut s = p;
        while s + 1 < count && knots[s + 1] <= knots[p] {
            s += 1;
        }
        return s;
    }
    // Binary search in [p, count): knots[lo] <= t < knots[hi].
    let (mut lo, mut hi) = (p, count);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if t < knots[mid] {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    lo
}

/// Values and up to `nd` (<= 2) derivatives of the p + 1 basis functions non-zero at t.
pub fn basis_row(knots: &[f64], count: usize, p: usize, t: f64, nd: usize) -> BasisRow {
    let span = find_span(knots, count, p, t);
    let t = t.clamp(knots[p], knots[count]);
    // ndu[j][r]: basis values of degree j in the upper triangle, knot differences below.
    let mut ndu = [[0.0f64; W]; W];
    let mut left = [0.0f64; W];
    let mut right = [0.0f64; W];
    ndu[0][0] = 1.0;
    for j in 1..=p {
        left[j] = t - knots[span + 1 - j];
        right[j] = knots[span + j] - t;
        let mut saved = 0.0;
        for r in 0..j {
            ndu[j][r] = right[r + 1] + left[j - r];
            let tmp = ndu[r][j - 1] / ndu[j][r];
            ndu[r][j] = saved + right[r + 1] * tmp;
            saved = left[j - r] * tmp;
        }
        ndu[j][j] = saved;
    }
    let mut d = [[0.0f64; W]; 3];
    for (r, v) in d[0].iter_mut().enumerate().take(p + 1) {
        *v = ndu[r][p];
    }
    let nd = nd.min(2).min(p);
    // Derivatives from differences of lower-degree functions, two alternating rows.
    let mut a = [[0.0f64; W]; 2];
    for r in 0..=p {
        let (mut s1, mut s2) = (0usize, 1usize);
        a[0][0] = 1.0;
        for k in 1..=nd {
            let mut dk = 0.0;
            let rk = r as isize - k as isize;
            let pk = p - k;
            if rk >= 0 {
                a[s2][0] = a[s1][0] / ndu[pk + 1][rk as usize];
                dk = a[s2][0] * ndu[rk as usize][pk];
            }
            let j1 = if rk >= -1 { 1 } else { (-rk) as usize };
            let j2 = if (r as isize) - 1 <= pk as isize {
                k - 1
            } else {
                p - r
            };
            for j in j1..=j2 {
                let idx = (rk + j as isize) as usize;
                a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][idx];
                dk += a[s2][j] * ndu[idx][pk];
            }
            if r <= pk {
                a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
                dk += a[s2][k] * ndu[r][pk];
            }
            d[k][r] = dk;
            std::mem::swap(&mut s1, &mut s2);
        }
    }
    // Multiply through by p!/(p-k)!.
    let mut f = p as f64;
    for (k, row) in d.iter_mut().enumerate().take(nd + 1).skip(1) {
        for v in row.iter_mut().take(p + 1) {
            *v *= f;
        }
        f *= (p - k) as f64;
    }
    BasisRow { span, d }
}

/// The textbook Cox-de Boor recursion for one function (0/0 taken as 0). Exponential in p;
/// kept as an independent reference for tests.
pub fn cox_de_boor(knots: &[f64], i: usize, p: usize, t: f64) -> f64 {
    if p == 0 {
        return if knots[i] <= t && t < knots[i + 1] {
            1.0
        } else {
            0.0
        };
    }
    let mut v = 0.0;
    let d1 = knots[i + p] - knots[i];
    if d1 > 0.0 {
        v += (t - knots[i]) / d1 * cox_de_boor(knots, i, p - 1, t);
    }
    let d2 = knots[i + p + 1] - knots[i + 1];
    if d2 > 0.0 {
        v += (knots[i + p + 1] - t) / d2 * cox_de_boor(knots, i + 1, p - 1, t);
    }
    v
}

/// How data points are given parameters along a curve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ParamMethod {
    /// Proportional to the distance between consecutive points (the documents' choice).
    #[default]
    ChordLength,
    /// Proportional to the square root of the distance (Lee): follows sharp turns better.
    Centripetal,
    /// Equally spaced.
    Uniform,
}

/// Parameters in [0, 1] for points in order. Coincident points share a parameter; all
/// points coinciding falls back to uniform spacing.
pub fn parameters(points: &[DVec3], method: ParamMethod) -> Vec<f64> {
    let n = points.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let steps: Vec<f64> = points
        .windows(2)
        .map(|w| {
            let d = (w[1] - w[0]).length();
            match method {
                ParamMethod::ChordLength => d,
                ParamMethod::Centripetal => d.sqrt(),
                ParamMethod::Uniform => 1.0,
            }
        })
        .collect();
    let total: f64 = steps.iter().sum();
    if total <= 0.0 || !total.is_finite() {
        return (0..n).map(|k| k as f64 / (n - 1) as f64).collect();
    }
    let mut t = Vec::with_capacity(n);
    let mut acc = 0.0;
    t.push(0.0);
    for s in &steps[..n - 2] {
        acc += s;
        t.push(acc / total);
    }
    t.push(1.0);
    t
}

/// Clamped knots for interpolation by de Boor's averaging: interior knot j is the mean of
/// p consecutive parameters, which keeps the collocation matrix nonsingular.
pub(crate) fn averaging_knots(params: &[f64], p: usize) -> Vec<f64> {
    let n = params.len();
    let mut k = vec![0.0; p + 1];
    for j in 1..n - p {
        k.push(params[j..j + p].iter().sum::<f64>() / p as f64);
    }
    k.extend(std::iter::repeat_n(1.0, p + 1));
    k
}

/// Clamped knots for a least-squares fit of `params.len()` points by `count` control
/// points: every knot span receives at least one parameter (the averaging rule for
/// approximation), so the least-squares matrix has full rank.
pub fn approximation_knots(params: &[f64], count: usize, p: usize) -> Vec<f64> {
    let m = params.len();
    let mut k = vec![0.0; p + 1];
    let d = m as f64 / (count - p) as f64;
    for j in 1..count - p {
        let x = j as f64 * d;
        let i = (x.floor() as usize).clamp(1, m - 1);
        let a = x - i as f64;
        k.push((1.0 - a) * params[i - 1] + a * params[i]);
    }
    k.extend(std::iter::repeat_n(1.0, p + 1));
    k
}

/// Schoenberg-Whitney: a strictly increasing choice of parameters with N_i(t) > 0 for every
/// basis function exists. Without it the least-squares matrix is rank deficient.
pub(crate) fn schoenberg_whitney(
    knots: &[f64],
    count: usize,
    p: usize,
    sorted_params: &[f64],
) -> bool {
    // Greedy: give each function the first unused parameter past the start of its support.
    let mut k = 0;
    for i in 0..count {
        let (a, b) = (knots[i], knots[i + p + 1]);
        while k < sorted_params.len()
            && !(sorted_params[k] > a || (i == 0 && sorted_params[k] >= a))
        {
            k += 1;
        }
        let Some(&t) = sorted_params.get(k) else {
            return false;
        };
        if !(t < b || (i == count - 1 && t <= b)) {
            return false;
        }
        k += 1;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn knots() -> (Vec<f64>, usize, usize) {
        // Degree 3, 8 control points, one double interior knot.
        (
            vec![0.0, 0.0, 0.0, 0.0, 0.2, 0.5, 0.5, 0.7, 1.0, 1.0, 1.0, 1.0],
            8,
            3,
        )
    }

    #[test]
    fn row_matches_cox_de_boor() {
        let (k, n, p) = knots();
        for s in 0..=97 {
            let t = s as f64 / 97.0 * 0.999_999;
            let row = basis_row(&k, n, p, t, 0);
            for r in 0..=p {
                let i = row.first(p) + r;
                let reference = cox_de_boor(&k, i, p, t);
                assert!((row.d[0][r] - reference).abs() < 1e-14, "t={t} i={i}");
            }
        }
    }

    #[test]
    fn span_at_the_ends_and_on_knots() {
        let (k, n, p) = knots();
        assert_eq!(find_span(&k, n, p, 0.0), 3);
        assert_eq!(find_span(&k, n, p, 1.0), 7);
        assert_eq!(find_span(&k, n, p, 0.5), 6);
        assert_eq!(find_span(&k, n, p, 0.49), 4);
        assert_eq!(find_span(&k, n, p, -3.0), 3);
    }

    #[test]
    fn validation_rejects_bad_vectors() {
        assert!(validate_knots(&[0.0, 0.0, 1.0, 1.0], 2, 1).is_ok());
        assert!(validate_knots(&[0.0, 0.0, 1.0], 2, 1).is_err());
        assert!(validate_knots(&[0.0, 1.0, 0.5, 1.0], 2, 1).is_err());
        assert!(validate_knots(&[0.0, 0.0, 0.0, 0.0], 2, 1).is_err());
        assert!(validate_knots(&[0.0, 0.0, 0.5, 0.5, 0.5, 1.0, 1.0], 5, 1).is_err());
    }

    #[test]
    fn schoenberg_whitney_detects_empty_spans() {
        let k = vec![0.0, 0.0, 0.0, 0.5, 0.6, 1.0, 1.0, 1.0];
        assert!(schoenberg_whitney(&k, 5, 2, &[0.0, 0.3, 0.55, 0.8, 1.0]));
        assert!(!schoenberg_whitney(&k, 5, 2, &[0.0, 0.1, 0.2, 0.3, 1.0]));
    }
}
