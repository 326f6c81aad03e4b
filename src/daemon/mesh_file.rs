//! The daemon's checked read of a mesh: a patch's file or pipe payload (`job`) and each
//! scan of an object (`object_job`) go through the same two steps, so both refuse the same
//! inputs with the same kinds:
//! - `read_file_bytes`: a known format, `daemon.max_file_bytes` checked before the read
//!   (one file must not exhaust memory), and the file's stamp before the read, for
//!   `still_changing` afterwards;
//! - `parse_mesh`: the reader under the daemon's limits, then `daemon.max_vertices`.

use super::config::DaemonSection;
use super::kinds::{rejection_kind, Cause};
use super::outcome::Outcome;
use crate::io::{read_with_base, Format, IoErrorKind, LoadOptions};
use crate::TriMesh;
use std::path::Path;
use std::time::{Duration, SystemTime};

/// Why a mesh was not taken.
#[derive(Debug)]
pub(crate) struct Refused {
    /// `kinds::rejection_kind` of the cause.
    pub kind: &'static str,
    pub reason: String,
    /// A readable mesh the daemon will not fit (over `max_vertices`), as against a broken
    /// or unreadable file.
    pub unsupported: bool,
    /// A `.gltf` whose external buffer is not in its folder (yet: the two files of a glTF
    /// are copied one after the other).
    pub buffer_missing: bool,
}

impl Refused {
    fn new(cause: Cause<'_>, reason: String) -> Self {
        let buffer_missing = matches!(
            cause,
            Cause::Parse(e) if matches!(
                &e.kind,
                IoErrorKind::ExternalBuffer { source, .. }
                    if source.kind() == std::io::ErrorKind::NotFound
            )
        );
        Self {
            unsupported: matches!(cause, Cause::TooManyVertices),
            kind: rejection_kind(&cause),
            reason,
            buffer_missing,
        }
    }

    /// The `Incomplete` outcome of a `.gltf` at `path` whose buffer is missing and which
    /// came into its folder less than `BUFFER_WAIT` ago (its buffer may still be on its
    /// way), for a patch's file and for an object's scan alike; `None` otherwise.
    pub(crate) fn awaiting_buffer(&self, path: &Path) -> Option<Outcome> {
        (self.buffer_missing && arrived_within(path, BUFFER_WAIT)).then(|| Outcome::Incomplete {
            reason: format!(
                "{}; the glTF arrived less than {} s ago, so its buffer may still be on its \
                 way: looked for again every second",
                self.reason,
                BUFFER_WAIT.as_secs()
            ),
            wait: Some(BUFFER_RETRY),
        })
    }
}

/// How long a `.gltf` whose external buffer is missing waits for it before it is
/// quarantined: copying a model's files one by one takes seconds, not minutes.
const BUFFER_WAIT: Duration = Duration::from_secs(60);
/// How often it looks for the buffer meanwhile (the `.bin` itself is no mesh, so its
/// arrival is no event of the watch).
const BUFFER_RETRY: Duration = Duration::from_secs(1);

/// Whether `path` came into its folder less than `wait` ago, by its inode change time: a
/// copy or a rename into the folder sets it, while copies that keep the modification time
/// (`cp -p`, rsync, file managers) leave an old mtime. A file that cannot be stat'ed did not.
fn arrived_within(path: &Path, wait: Duration) -> bool {
    use std::os::unix::fs::MetadataExt;
    let Ok(meta) = std::fs::metadata(path) else {
        return false;
    };
    let changed = std::time::UNIX_EPOCH + Duration::new(meta.ctime().max(0) as u64, 0);
    SystemTime::now()
        .duration_since(changed)
        .is_ok_and(|age| age < wait)
}

/// A mesh file's bytes, read within the limits.
pub(crate) struct FileBytes {
    pub format: Format,
    pub bytes: Vec<u8>,
    /// Size and mtime before the read: `still_changing` compares them after it.
    pub stamp: (u64, Option<SystemTime>),
}

/// The error for bytes over `daemon.max_file_bytes`.
pub(crate) fn too_large(len: u64, limits: &DaemonSection) -> Refused {
    Refused::new(
        Cause::TooLarge,
        format!(
            "{len} bytes exceeds daemon.max_file_bytes = {}",
            limits.max_file_bytes
        ),
    )
}

/// Reads a mesh file whose format its extension names, refusing it before the read when it
/// is over `daemon.max_file_bytes`.
pub(crate) fn read_file_bytes(path: &Path, limits: &DaemonSection) -> Result<FileBytes, Refused> {
    let Some(format) = Format::from_path(path) else {
        return Err(Refused::new(
            Cause::UnknownFormat,
            format!("unknown extension ({})", Format::READABLE),
        ));
    };
    let unreadable = |e: std::io::Error| Refused::new(Cause::Read(&e), format!("cannot read: {e}"));
    let meta = std::fs::metadata(path).map_err(unreadable)?;
    if meta.len() > limits.max_file_bytes {
        return Err(too_large(meta.len(), limits));
    }
    let bytes = std::fs::read(path).map_err(unreadable)?;
    if bytes.len() as u64 > limits.max_file_bytes {
        // It grew between the stat and the read.
        return Err(too_large(bytes.len() as u64, limits));
    }
    Ok(FileBytes {
        format,
        bytes,
        stamp: (meta.len(), meta.modified().ok()),
    })
}

/// Parses a mesh under the daemon's limits. `folder` is where a file's external glTF
/// buffers may lie (the reader confines them to it); pipe payloads have none and must embed
/// theirs.
pub(crate) fn parse_mesh(
    bytes: &[u8],
    format: Format,
    label: &str,
    limits: &DaemonSection,
    folder: Option<&Path>,
) -> Result<TriMesh, Refused> {
    let load = LoadOptions::with_limits(limits.max_file_bytes, limits.max_vertices);
    match read_with_base(bytes, format, label, &load, folder) {
        Ok(l) if l.mesh.positions.len() > limits.max_vertices => Err(Refused::new(
            Cause::TooManyVertices,
            format!(
                "{} vertices exceeds daemon.max_vertices = {}",
                l.mesh.positions.len(),
                limits.max_vertices
            ),
        )),
        Ok(l) => Ok(l.mesh),
        Err(e) => Err(Refused::new(Cause::Parse(&e), e.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(max_file_bytes: u64, max_vertices: usize) -> DaemonSection {
        let mut cfg = super::super::config::DaemonConfig::embedded_default().expect("default");
        cfg.daemon.max_file_bytes = max_file_bytes;
        cfg.daemon.max_vertices = max_vertices;
        cfg.daemon
    }

    const TRIANGLE_OFF: &[u8] = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";

    #[test]
    fn the_format_the_size_and_the_vertex_cap_are_each_refused_by_their_kind() {
        let dir = tempfile::tempdir().expect("tmp");
        let odd = dir.path().join("a.xyzzy");
        std::fs::write(&odd, TRIANGLE_OFF).expect("write");
        let e = read_file_bytes(&odd, &limits(1 << 20, 100))
            .err()
            .expect("refused");
        assert_eq!(e.kind, "unknown_format");
        let off = dir.path().join("a.off");
        std::fs::write(&off, TRIANGLE_OFF).expect("write");
        let e = read_file_bytes(&off, &limits(10, 100))
            .err()
            .expect("refused");
        assert_eq!((e.kind, e.unsupported), ("too_large", false));
        let e = read_file_bytes(&dir.path().join("gone.off"), &limits(1 << 20, 100))
            .err()
            .expect("refused");
        assert_eq!(e.kind, "read_not_found");
        let read = read_file_bytes(&off, &limits(1 << 20, 100)).expect("read");
        assert_eq!(read.stamp.0, TRIANGLE_OFF.len() as u64);
        let mesh = parse_mesh(&read.bytes, read.format, "a.off", &limits(1 << 20, 3), None);
        assert_eq!(mesh.expect("parsed").positions.len(), 3);
        let e = parse_mesh(&read.bytes, read.format, "a.off", &limits(1 << 20, 2), None)
            .expect_err("over the cap");
        // The reader refuses a declared count over the cap before it allocates; formats
        // without one are caught after the parse.
        assert!(matches!(e.kind, "too_large" | "too_many_vertices"), "{e:?}");
        let e = parse_mesh(
            b"OFF\n3 1",
            Format::Off,
            "cut.off",
            &limits(1 << 20, 9),
            None,
        )
        .expect_err("cut");
        assert!(!e.unsupported && e.reason.contains("cut.off"), "{e:?}");
    }
}
