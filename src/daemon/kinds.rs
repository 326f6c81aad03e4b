//! The machine-readable `kind` of a rejection, beside the human `reason` in events and as
//! the only label of the rejection metrics (free text would make one series per file).
//!
//! Classified here, in one place: when the reader and pipeline errors carry a `kind()` of
//! their own, `Cause::Parse` and `Cause::Pipeline` ask them instead.

use super::confine::Refusal;

/// What went wrong with an input or a pipe record. The errors ride along although only
/// their variant is read today: they are what `rejection_kind` will ask for their own kind.
#[allow(dead_code)]
pub(crate) enum Cause<'a> {
    /// The file could not be read (gone, permissions).
    Read(&'a std::io::Error),
    /// Over `daemon.max_file_bytes`.
    TooLarge,
    /// Over `daemon.max_vertices`.
    TooManyVertices,
    /// The extension names no known format.
    UnknownFormat,
    /// The file name leaves no usable patch id.
    NoPatchId,
    /// The reader refused the bytes.
    Parse(&'a crate::io::IoError),
    /// The pipeline refused the mesh.
    Pipeline(&'a crate::pipeline::PipelineError),
    /// A worker panicked on it (caught).
    Panic,
    /// A pipe path record named a file the daemon may not take.
    Path(&'a Refusal),
    /// A pipe record that is not a valid record.
    Record(RecordFault),
}

/// The ways a pipe record can be malformed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RecordFault {
    LineTooLong,
    NotJson,
    NoPatch,
    UnknownKeys,
    BadLength,
    BadFormat,
    PathAndBytes,
    NoPathNorBytes,
    /// The stream ended (or the daemon stopped) inside the payload.
    Truncated,
}

/// The `kind` string of a rejection.
pub(crate) fn rejection_kind(cause: &Cause<'_>) -> &'static str {
    match cause {
        Cause::Read(_) => "read_failed",
        Cause::TooLarge => "too_large",
        Cause::TooManyVertices => "too_many_vertices",
        Cause::UnknownFormat => "unknown_format",
        Cause::NoPatchId => "no_patch_id",
        Cause::Parse(_) => "parse_failed",
        Cause::Pipeline(_) => "pipeline_refused",
        Cause::Panic => "panic",
        Cause::Path(r) => r.kind(),
        Cause::Record(f) => match f {
            RecordFault::LineTooLong => "record_line_too_long",
            RecordFault::NotJson => "record_not_json",
            RecordFault::NoPatch => "record_no_patch",
            RecordFault::UnknownKeys => "record_unknown_keys",
            RecordFault::BadLength => "record_bad_length",
            RecordFault::BadFormat => "record_bad_format",
            RecordFault::PathAndBytes => "record_path_and_bytes",
            RecordFault::NoPathNorBytes => "record_no_path_nor_bytes",
            RecordFault::Truncated => "record_truncated",
        },
    }
}
