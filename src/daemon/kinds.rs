//! The machine-readable `kind` of a rejection, beside the human `reason` in events and as
//! the only label of the rejection metrics (free text would make one series per file).
//!
//! Classified here, in one place. The reader's and the pipeline's errors name their own
//! kind (`IoError::kind`, `PipelineError::kind`: stable snake_case names from a fixed set),
//! so a rejection says which refusal it was ("truncated", "not_disk_like"), not only that
//! parsing or fitting failed.

use super::confine::Refusal;

/// What went wrong with an input or a pipe record.
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
    /// An "object" that leaves no id, or a "transform" that is not 16 numbers of a rigid
    /// motion (or comes without an "object").
    BadObject,
}

/// The `kind` string of a rejection.
pub(crate) fn rejection_kind(cause: &Cause<'_>) -> &'static str {
    match cause {
        Cause::Read(e) => match e.kind() {
            std::io::ErrorKind::NotFound => "read_not_found",
            std::io::ErrorKind::PermissionDenied => "read_permission_denied",
            _ => "read_failed",
        },
        Cause::TooLarge => "too_large",
        Cause::TooManyVertices => "too_many_vertices",
        Cause::UnknownFormat => "unknown_format",
        Cause::NoPatchId => "no_patch_id",
        Cause::Parse(e) => e.kind(),
        Cause::Pipeline(e) => e.kind(),
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
            RecordFault::BadObject => "record_bad_object",
        },
    }
}
