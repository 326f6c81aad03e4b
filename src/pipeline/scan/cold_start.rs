//! Why a scan fit that was given a previous version started cold, and the limits behind
//! those reasons. Apart from the guard that applies them (`warm_guard`), so that the scan's
//! result type can carry the reason without importing the guard.

/// Why a fit that was given a previous version started cold.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
#[non_exhaustive]
pub enum ColdStart {
    /// Too many new points lie where the previous version had no data.
    Coverage {
        /// Share of the new points farther than `NEW_GROUND_REACH_EDGES` sample spacings
        /// from every previous point.
        outside_share: f64,
    },
    /// The piece fitted is not the previous piece: far fewer points, or most of the input
    /// fell apart into pieces.
    Pieces {
        /// Vertices of the piece fitted now...
        vertices: usize,
        /// ... and of the previous version's.
        previous: usize,
        /// Share of the input's vertices in pieces left out.
        dropped_share: f64,
    },
    /// The data face another way: the angle between the mean normals.
    Frame {
        /// Degrees.
        normal_angle_deg: f64,
    },
    /// The data moved: how far the new bounding box sticks out of the previous one.
    Shift {
        /// As a share of the previous bounding-box diagonal.
        diagonal_share: f64,
    },
    /// The previous grid spacing would give more controls than the budget allows.
    Budget {
        /// Controls the previous spacing gives over the new data...
        controls: usize,
        /// ... and the most a warm start may have.
        limit: usize,
    },
}

impl std::fmt::Display for ColdStart {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            ColdStart::Coverage { outside_share } => write!(
                f,
                "coverage: {:.1} % of the new points lie outside the previous version's data (limit {:.0} %)",
                100.0 * outside_share,
                100.0 * MAX_OUTSIDE_SHARE
            ),
            ColdStart::Pieces {
                vertices,
                previous,
                dropped_share,
            } => write!(
                f,
                "pieces: the piece fitted has {vertices} vertices, the previous one {previous}, and {:.1} % of the input lies in pieces left out",
                100.0 * dropped_share
            ),
            ColdStart::Frame { normal_angle_deg } => write!(
                f,
                "frame: the mean normal turned by {normal_angle_deg:.1} degrees (limit {MAX_NORMAL_ANGLE_DEG:.0})"
            ),
            ColdStart::Shift { diagonal_share } => write!(
                f,
                "frame: the bounding box sticks out of the previous one by {:.1} % of its diagonal (limit {:.0} %)",
                100.0 * diagonal_share,
                100.0 * MAX_SHIFT_SHARE
            ),
            ColdStart::Budget { controls, limit } => write!(
                f,
                "budget: the previous grid spacing gives {controls} controls over the new data, more than {limit}"
            ),
        }
    }
}

/// A rescan's points sit within a sample spacing or so of the previous ones; a point
/// farther than this many median edge lengths from all of them is on new ground.
pub(super) const NEW_GROUND_REACH_EDGES: f64 = 3.0;

/// Share of new points on new ground beyond which the previous net is no start: its
/// controls there were never fitted to anything.
pub(super) const MAX_OUTSIDE_SHARE: f64 = 0.1;

/// Shrink of the vertex count beyond which the piece fitted is taken for a fragment of the
/// previous one. Only a shrink counts: a denser rescan of the same ground has more points and
/// is the best case for a warm start, and growth onto new ground is judged by coverage.
pub(super) const MAX_SIZE_RATIO: f64 = 1.5;

/// Share of the input in pieces left out beyond which the input is taken to have fallen
/// apart (a version with a fifth of its vertices missing at random had 633 pieces).
pub(super) const MAX_DROPPED_SHARE: f64 = 0.25;

/// Turn of the mean normal against the previous plane's normal beyond which that plane is
/// no longer the data's. The previous plane is the one with the fewest folds, not the mean
/// normal's: on bun000 they differ by about 15 degrees once a fifth of the scan is cut
/// away, so only a clearly larger turn counts.
pub(super) const MAX_NORMAL_ANGLE_DEG: f64 = 25.0;

/// How far (share of the previous diagonal) the new bounding box may stick out of the
/// previous one before the data count as moved.
pub(super) const MAX_SHIFT_SHARE: f64 = 0.05;
