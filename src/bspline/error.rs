//! What can go wrong building or fitting a B-spline; shared by every file of the module.

/// Highest degree handled: basis rows live in fixed stack arrays of this size + 1. Kept
/// here, beside the error that enforces it, and re-exported as `basis::MAX_DEGREE`.
pub const MAX_DEGREE: usize = 15;

/// A B-spline that cannot be built or fitted as asked; each variant says which input to
/// change.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum BSplineError {
    /// The degree is 0 or above `basis::MAX_DEGREE`.
    #[error("degree {0} is outside 1..={max}", max = MAX_DEGREE)]
    Degree(usize),
    /// Fewer control points than degree + 1.
    #[error("{count} control points cannot carry degree {degree} (need at least degree + 1)")]
    TooFewControls {
        /// Control points given.
        count: usize,
        /// Degree asked for.
        degree: usize,
    },
    /// The knot vector's length does not match count + degree + 1.
    #[error("knot vector: {knots} knots for {count} control points of degree {degree} (need {count} + {})", degree + 1)]
    KnotCount {
        /// Knots given.
        knots: usize,
        /// Control points.
        count: usize,
        /// Degree.
        degree: usize,
    },
    /// A knot is not finite or the knots decrease somewhere.
    #[error("knot vector: knots must be finite and non-decreasing")]
    KnotOrder,
    /// The clamped parameter domain `[knots[p], knots[count]]` is empty.
    #[error("knot vector: empty parameter domain")]
    EmptyDomain,
    /// An interior knot repeats more than `degree` times, which would disconnect the curve.
    #[error("knot vector: interior knot {knot} repeated more than {degree} times")]
    KnotMultiplicity {
        /// The repeated knot value.
        knot: f64,
        /// Degree (the largest multiplicity allowed).
        degree: usize,
    },
    /// The number of control points does not match the control grid.
    #[error("{got} control points given, {expected} expected")]
    ControlCount {
        /// Control points given.
        got: usize,
        /// Control points the grid needs.
        expected: usize,
    },
    /// Fewer data points than unknowns.
    #[error("{points} data points cannot determine {controls} control points")]
    TooFewPoints {
        /// Data points given.
        points: usize,
        /// Control points asked for.
        controls: usize,
    },
    /// A data or control coordinate is NaN or infinite (index of the first such point).
    #[error("non-finite coordinate in the data (point {0})")]
    NonFinite(usize),
    /// The least-squares system has no unique solution.
    #[error("the least-squares system is rank deficient at unknown {0} (data leaves a knot span empty; add smoothing or fewer control points)")]
    RankDeficient(usize),
}

impl BSplineError {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Degree(_) => "degree",
            Self::TooFewControls { .. } => "too_few_controls",
            Self::KnotCount { .. } => "knot_count",
            Self::KnotOrder => "knot_order",
            Self::EmptyDomain => "empty_domain",
            Self::KnotMultiplicity { .. } => "knot_multiplicity",
            Self::ControlCount { .. } => "control_count",
            Self::TooFewPoints { .. } => "too_few_points",
            Self::NonFinite(_) => "non_finite",
            Self::RankDeficient(_) => "rank_deficient",
        }
    }
}
