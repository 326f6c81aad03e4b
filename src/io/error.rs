//! The one error type of the readers and writers: which file, where in it, and a typed
//! kind with a stable name (`IoError::kind`) that machine consumers (the daemon's
//! rejection events) can match on while people read the message.

use crate::bspline::BSplineError;
use crate::mesh::rigid::RigidError;
use crate::surface::loop_limit::LoopLimitError;

/// A reader or writer failure, always naming the file and, where known, where in it.
///
/// The message is complete on its own (it quotes the cause, if any), so `source()` is
/// `None`: chained printers (`{:#}`) would otherwise repeat the cause. The typed cause
/// sits in `kind`; match on it, or ask it for its `source()`.
#[derive(Debug)]
pub struct IoError {
    /// The file as given (a path, or the name of an in-memory input).
    pub file: String,
    /// "line 12", "byte 4096", "key degree": whatever the reader knows.
    pub location: Option<String>,
    /// What went wrong.
    pub kind: IoErrorKind,
}

impl std::fmt::Display for IoError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = &self.location {
            write!(f, " ({l})")?;
        }
        write!(f, ": {}", self.kind)
    }
}

impl std::error::Error for IoError {}

impl IoError {
    /// An error in `file`, at `location` if known.
    pub fn new(file: impl Into<String>, location: Option<String>, kind: IoErrorKind) -> Self {
        Self {
            file: file.into(),
            location,
            kind,
        }
    }

    /// An error at a place in `file` ("line 3", "key degree").
    pub(crate) fn at(
        file: impl Into<String>,
        location: impl Into<String>,
        kind: IoErrorKind,
    ) -> Self {
        Self::new(file, Some(location.into()), kind)
    }

    /// The kind's stable snake_case name (`"truncated"`, `"index_out_of_range"`, ...).
    pub fn kind(&self) -> &'static str {
        self.kind.name()
    }
}

/// What went wrong reading or writing a file. The `detail` strings say which record and
/// which value, in the file's own terms.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoErrorKind {
    /// The file could not be read.
    #[error("cannot read the file: {0}")]
    Open(#[source] std::io::Error),
    /// The file (or a temp file beside it) could not be written, synced or renamed.
    #[error("cannot write the file: {0}")]
    Write(#[source] std::io::Error),
    /// The extension names no format this crate reads or writes.
    #[error("{0}")]
    UnknownExtension(&'static str),
    /// The file has no bytes (or, for text formats, no content lines).
    #[error("empty file")]
    Empty,
    /// The file parsed but holds no vertex.
    #[error("no vertices")]
    NoVertices,
    /// Text was expected and the bytes are not UTF-8.
    #[error("{what} is not UTF-8 text")]
    NotText {
        /// "the file", "the header", "a number".
        what: &'static str,
    },
    /// The header (PLY, OFF) cannot be understood.
    #[error("{detail}")]
    BadHeader {
        /// Which header line or field, and what is wrong with it.
        detail: String,
    },
    /// The file ends before the records its header declares.
    #[error("{detail}")]
    Truncated {
        /// Where the data stopped.
        detail: String,
    },
    /// A declared count is larger than the file could hold: refused before allocating.
    #[error("{detail}")]
    TooLarge {
        /// The count and the room there is for it.
        detail: String,
    },
    /// Two numbers that must agree do not (declared vs present, cells vs grid size).
    #[error("{detail}")]
    CountMismatch {
        /// Both numbers.
        detail: String,
    },
    /// A face or primitive refers to a vertex that does not exist.
    #[error("{detail}")]
    IndexOutOfRange {
        /// The record, the index and the valid range.
        detail: String,
    },
    /// A coordinate is NaN or infinite.
    #[error("{detail}")]
    NonFinite {
        /// The record holding it.
        detail: String,
    },
    /// A record that cannot be read: a word that is no number, a face with too few
    /// vertices, a broken structure.
    #[error("{detail}")]
    Malformed {
        /// The record and what is wrong with it.
        detail: String,
    },
    /// A valid file using a feature this crate does not handle.
    #[error("{what}")]
    Unsupported {
        /// The feature, and what to do instead where there is an alternative.
        what: String,
    },
    /// The glTF parser refused the file.
    #[error("glTF parse error: {0}")]
    Gltf(#[source] gltf::Error),
    /// An external glTF buffer could not be read.
    #[error("buffer '{uri}': {source}")]
    ExternalBuffer {
        /// The buffer's URI as written in the file.
        uri: String,
        /// Why it could not be read.
        #[source]
        source: std::io::Error,
    },
    /// The STL parser refused the file.
    #[error("STL parse error: {0}")]
    Stl(#[source] std::io::Error),
    /// The file is not valid JSON.
    #[error("{0}")]
    Json(#[source] serde_json::Error),
    /// Valid JSON that does not follow the schema: a key missing or of the wrong type or
    /// range.
    #[error("{detail}")]
    Schema {
        /// What the key should hold.
        detail: String,
    },
    /// The control mesh of a Loop surface is not one the surface can be built on.
    #[error("{0}")]
    LoopSurface(#[source] LoopLimitError),
    /// The B-spline described is not a valid one.
    #[error("{0}")]
    BSpline(#[source] BSplineError),
    /// A registration (`.xf`, `.conf` line, pipe `transform`) that is no rigid motion.
    #[error("not a rigid transform: {0}")]
    NotRigid(#[source] RigidError),
}

impl IoErrorKind {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Open(_) => "open",
            Self::Write(_) => "write",
            Self::UnknownExtension(_) => "unknown_extension",
            Self::Empty => "empty",
            Self::NoVertices => "no_vertices",
            Self::NotText { .. } => "not_text",
            Self::BadHeader { .. } => "bad_header",
            Self::Truncated { .. } => "truncated",
            Self::TooLarge { .. } => "too_large",
            Self::CountMismatch { .. } => "count_mismatch",
            Self::IndexOutOfRange { .. } => "index_out_of_range",
            Self::NonFinite { .. } => "non_finite",
            Self::Malformed { .. } => "malformed",
            Self::Unsupported { .. } => "unsupported",
            Self::Gltf(_) => "gltf",
            Self::ExternalBuffer { .. } => "external_buffer",
            Self::Stl(_) => "stl",
            Self::Json(_) => "json",
            Self::Schema { .. } => "schema",
            Self::LoopSurface(_) => "loop_surface",
            Self::BSpline(_) => "bspline",
            Self::NotRigid(_) => "not_rigid",
        }
    }

    pub(crate) fn bad_header(detail: impl Into<String>) -> Self {
        Self::BadHeader {
            detail: detail.into(),
        }
    }

    pub(crate) fn truncated(detail: impl Into<String>) -> Self {
        Self::Truncated {
            detail: detail.into(),
        }
    }

    pub(crate) fn too_large(detail: impl Into<String>) -> Self {
        Self::TooLarge {
            detail: detail.into(),
        }
    }

    pub(crate) fn count_mismatch(detail: impl Into<String>) -> Self {
        Self::CountMismatch {
            detail: detail.into(),
        }
    }

    pub(crate) fn index_out_of_range(detail: impl Into<String>) -> Self {
        Self::IndexOutOfRange {
            detail: detail.into(),
        }
    }

    pub(crate) fn non_finite(detail: impl Into<String>) -> Self {
        Self::NonFinite {
            detail: detail.into(),
        }
    }

    pub(crate) fn malformed(detail: impl Into<String>) -> Self {
        Self::Malformed {
            detail: detail.into(),
        }
    }

    pub(crate) fn unsupported(what: impl Into<String>) -> Self {
        Self::Unsupported { what: what.into() }
    }

    pub(crate) fn schema(detail: impl Into<String>) -> Self {
        Self::Schema {
            detail: detail.into(),
        }
    }
}
