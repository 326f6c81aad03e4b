//! Which files the daemon may read, move or delete because a pipe record named them: only
//! files under the configured roots (default: the watch folder). Judged on canonical paths,
//! so that `..` and symlinks cannot lead out: whoever can write to the FIFO must not be able
//! to make the daemon (which may run as root) move or remove files elsewhere.

use std::path::{Path, PathBuf};

/// Canonical root folders.
pub(crate) struct Roots {
    roots: Vec<PathBuf>,
}

/// Why a pipe path record was refused.
#[derive(Debug, thiserror::Error)]
pub(crate) enum Refusal {
    #[error("{path}: {}{source}", missing.as_ref().map(|m| format!("{m} does not exist: ")).unwrap_or_default())]
    Unresolvable {
        path: String,
        /// The first folder or file on the way that is not there (`bad` of `bad/../x`:
        /// the kernel resolves `..` after `bad`, so `x` existing is not enough).
        missing: Option<String>,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} resolves to {resolved}, outside the pipe roots ({roots}); set daemon.pipe_roots to allow it")]
    Outside {
        path: String,
        resolved: String,
        roots: String,
    },
    #[error("{path} is not a regular file")]
    NotAFile { path: String },
}

impl Refusal {
    /// Machine-readable kind for events and metrics.
    pub(crate) fn kind(&self) -> &'static str {
        match self {
            Refusal::Unresolvable { .. } => "path_unreadable",
            Refusal::Outside { .. } => "path_outside_roots",
            Refusal::NotAFile { .. } => "path_not_a_file",
        }
    }
}

impl Roots {
    /// The configured roots, or the watch folder when none are; roots that do not resolve
    /// (missing folders) are left out, with a warning.
    pub(crate) fn new(watch_dir: &Path, configured: &[PathBuf]) -> Self {
        let wanted: Vec<&Path> = if configured.is_empty() {
            vec![watch_dir]
        } else {
            configured.iter().map(PathBuf::as_path).collect()
        };
        let roots = wanted
            .into_iter()
            .filter_map(|r| {
                std::fs::canonicalize(r)
                    .map_err(
                        |e| tracing::warn!(root = %r.display(), error = %e, "pipe root unusable"),
                    )
                    .ok()
            })
            .collect();
        Self { roots }
    }

    fn inside(&self, canonical: &Path) -> bool {
        self.roots.iter().any(|r| canonical.starts_with(r))
    }

    /// The canonical path of a regular file under a root, or why not. A relative path is
    /// taken relative to `base` (the watch folder), not to the daemon's working folder.
    pub(crate) fn confine(&self, raw: &Path, base: &Path) -> Result<PathBuf, Refusal> {
        let path = raw.display().to_string();
        let full = base.join(raw);
        let resolved = std::fs::canonicalize(&full).map_err(|source| Refusal::Unresolvable {
            path: path.clone(),
            missing: first_missing(&full),
            source,
        })?;
        if !self.inside(&resolved) {
            let roots = self
                .roots
                .iter()
                .map(|r| r.display().to_string())
                .collect::<Vec<_>>()
                .join(", ");
            return Err(Refusal::Outside {
                path,
                resolved: resolved.display().to_string(),
                roots,
            });
        }
        match std::fs::metadata(&resolved) {
            Ok(m) if m.is_file() => Ok(resolved),
            Ok(_) => Err(Refusal::NotAFile { path }),
            Err(source) => Err(Refusal::Unresolvable {
                path,
                missing: None,
                source,
            }),
        }
    }

    /// Whether the directory entry `path` (not what a symlink there points to: renaming and
    /// removing act on the entry) sits in a folder under a root. Checked again right before
    /// moving or deleting, since the folders may have changed since the record was read.
    pub(crate) fn holds_entry(&self, path: &Path) -> bool {
        let (Some(parent), Some(_)) = (path.parent(), path.file_name()) else {
            return false;
        };
        std::fs::canonicalize(parent).is_ok_and(|p| self.inside(&p))
    }
}

/// The first prefix of `path` that does not exist, component by component as the kernel
/// walks it.
fn first_missing(path: &Path) -> Option<String> {
    let mut walked = PathBuf::new();
    for c in path.components() {
        walked.push(c);
        if std::fs::symlink_metadata(&walked).is_err() {
            return Some(walked.display().to_string());
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot_dot_absolute_and_symlinks_out_are_refused() {
        let tmp = tempfile::tempdir().expect("tmp");
        let root = tmp.path().join("root");
        let victim_dir = tmp.path().join("victim");
        std::fs::create_dir_all(root.join("sub")).expect("mkdir");
        std::fs::create_dir_all(&victim_dir).expect("mkdir");
        let victim = victim_dir.join("passwd.obj");
        std::fs::write(&victim, "v 0 0 0\n").expect("write");
        std::fs::write(root.join("sub/ok.obj"), "v 0 0 0\n").expect("write");
        std::os::unix::fs::symlink(&victim, root.join("link.obj")).expect("symlink");
        std::os::unix::fs::symlink(&victim_dir, root.join("dirlink")).expect("symlink");
        let roots = Roots::new(&root, &[]);
        let inside = roots
            .confine(&root.join("sub/../sub/ok.obj"), &root)
            .expect("inside");
        assert!(inside.ends_with("root/sub/ok.obj"));
        let relative = roots
            .confine(Path::new("sub/ok.obj"), &root)
            .expect("relative to the watch folder");
        assert_eq!(relative, inside);
        // `bad` does not exist, so `bad/..` does not resolve even though `sub` does: the
        // message names `bad`, not the file.
        let e = roots
            .confine(Path::new("bad/../sub/ok.obj"), &root)
            .expect_err("bad is missing");
        assert_eq!(e.kind(), "path_unreadable");
        let text = e.to_string();
        assert!(
            text.starts_with("bad/../sub/ok.obj: ") && text.contains("root/bad does not exist"),
            "{text}"
        );
        for bad in [
            victim.clone(),
            root.join("../victim/passwd.obj"),
            root.join("sub/../../victim/passwd.obj"),
            root.join("link.obj"),
            root.join("dirlink/passwd.obj"),
        ] {
            let e = roots.confine(&bad, &root).expect_err("outside");
            assert_eq!(e.kind(), "path_outside_roots", "{bad:?}: {e}");
        }
        assert_eq!(
            roots
                .confine(&root.join("sub"), &root)
                .expect_err("dir")
                .kind(),
            "path_not_a_file"
        );
        assert_eq!(
            roots
                .confine(&root.join("none.obj"), &root)
                .expect_err("none")
                .kind(),
            "path_unreadable"
        );
        assert!(
            roots.holds_entry(&root.join("link.obj")),
            "the entry is inside"
        );
        assert!(!roots.holds_entry(&root.join("dirlink/passwd.obj")));
        assert!(!roots.holds_entry(&victim));
        // Configured roots replace the watch folder.
        let wider = Roots::new(&root, &[tmp.path().to_path_buf()]);
        assert!(wider.confine(&victim, &root).is_ok());
    }
}
