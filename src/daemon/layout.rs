//! Where the quarantine may go. OUT holds one entry per patch (a symlink into
//! `OUT/.versions`) beside its own entries, so a quarantine configured inside OUT under any
//! name but `quarantine` (which no patch id can take) could become a patch's folder: patch
//! `bad` would try to publish over `OUT/bad`, or quarantined inputs would land in the
//! patch's version folder. The watch folder itself would hand quarantined inputs straight
//! back. Both are refused at start, before anything is written.

use std::path::{Component, Path, PathBuf};

/// A configured `output.quarantine_dir` the daemon will not use.
#[derive(Debug, thiserror::Error)]
pub(crate) enum Misplaced {
    /// Inside OUT, outside `OUT/quarantine`.
    #[error(
        "it resolves to {}, inside the output folder {}, where a patch of the same name could \
         take its place; use {}/quarantine (the default) or a folder outside it",
        resolved.display(), out.display(), out.display()
    )]
    InsideOutputs {
        /// The configured folder, resolved.
        resolved: PathBuf,
        /// The output folder, resolved.
        out: PathBuf,
    },
    /// The watch folder: quarantined inputs would arrive again.
    #[error("it resolves to the watch folder {}, which would take quarantined inputs back in", resolved.display())]
    WatchFolder {
        /// The configured folder, resolved.
        resolved: PathBuf,
    },
    /// No part of the path resolves (a permission problem, a dangling prefix).
    #[error("it cannot be resolved: {0}")]
    Unresolvable(#[source] std::io::Error),
}

/// The quarantine folder: `OUT/quarantine`, or the configured one when it can never
/// coincide with a patch's folder nor with the watch folder. `out_dir` and `watch_dir`
/// exist (the daemon made or listed them); the quarantine need not exist yet.
pub(crate) fn quarantine_folder(
    configured: Option<&Path>,
    out_dir: &Path,
    watch_dir: &Path,
) -> Result<PathBuf, Misplaced> {
    let Some(configured) = configured else {
        return Ok(out_dir.join("quarantine"));
    };
    let resolved = resolve(configured).map_err(Misplaced::Unresolvable)?;
    let out = resolve(out_dir).map_err(Misplaced::Unresolvable)?;
    if resolve(watch_dir).is_ok_and(|w| w == resolved) {
        return Err(Misplaced::WatchFolder { resolved });
    }
    if let Ok(below) = resolved.strip_prefix(&out) {
        let first = below.components().next();
        if first != Some(Component::Normal("quarantine".as_ref())) {
            return Err(Misplaced::InsideOutputs { resolved, out });
        }
    }
    Ok(configured.to_path_buf())
}

/// The canonical form of a path that may not exist yet: its longest existing prefix
/// canonicalised (symlinks and `..` resolved by the filesystem), the rest appended
/// lexically. The rest does not exist, so it holds no symlinks to follow.
fn resolve(path: &Path) -> std::io::Result<PathBuf> {
    let absolute = std::path::absolute(path)?;
    let parts: Vec<Component> = absolute.components().collect();
    let mut last_error = None;
    for split in (1..=parts.len()).rev() {
        let prefix: PathBuf = parts[..split].iter().collect();
        match std::fs::canonicalize(&prefix) {
            Ok(mut real) => {
                for part in &parts[split..] {
                    match part {
                        Component::ParentDir => {
                            real.pop();
                        }
                        Component::Normal(name) => real.push(name),
                        Component::CurDir | Component::RootDir | Component::Prefix(_) => {}
                    }
                }
                return Ok(real);
            }
            Err(e) => last_error = Some(e),
        }
    }
    Err(last_error.unwrap_or_else(|| std::io::Error::other("an empty path")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarantine_inside_out_is_only_accepted_under_out_quarantine() {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("out");
        let watch = tmp.path().join("in");
        std::fs::create_dir_all(out.join("existing")).expect("out");
        std::fs::create_dir_all(&watch).expect("in");
        std::os::unix::fs::symlink(&out, tmp.path().join("out-link")).expect("link");
        let judge = |q: &Path| quarantine_folder(Some(q), &out, &watch);
        assert_eq!(
            quarantine_folder(None, &out, &watch).expect("default"),
            out.join("quarantine")
        );
        for fine in [
            out.join("quarantine"),
            out.join("quarantine/deeper"),
            tmp.path().join("elsewhere/q"),
            watch.join("sub/../../q"),
        ] {
            assert_eq!(judge(&fine).expect("accepted"), fine);
        }
        for inside in [
            out.join("bad"),
            out.join("existing"),
            out.join("new/deeper"),
            out.clone(),
            out.join(".versions"),
            out.join("quarantine/../bad"),
            tmp.path().join("out-link/bad"),
            tmp.path().join("in/../out/x"),
        ] {
            let err = judge(&inside).expect_err("refused");
            assert!(
                matches!(err, Misplaced::InsideOutputs { .. }),
                "{}: {err}",
                inside.display()
            );
            assert!(err.to_string().contains("quarantine"), "{err}");
        }
        let err = judge(&tmp.path().join("in/sub/..")).expect_err("the watch folder");
        assert!(matches!(err, Misplaced::WatchFolder { .. }), "{err}");
    }

    #[test]
    fn resolve_follows_links_in_the_existing_prefix_only() {
        let tmp = tempfile::tempdir().expect("tmp");
        let real = tmp.path().join("real");
        std::fs::create_dir(&real).expect("real");
        std::os::unix::fs::symlink(&real, tmp.path().join("link")).expect("link");
        let canonical = std::fs::canonicalize(&real).expect("canonical");
        assert_eq!(
            resolve(&tmp.path().join("link/a/b/../c")).expect("resolves"),
            canonical.join("a/c")
        );
        assert_eq!(
            resolve(&tmp.path().join("link/..")).expect("resolves"),
            canonical.parent().expect("parent")
        );
    }
}
