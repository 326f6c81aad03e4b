//! Crash-consistent output sets. Each version of a patch's outputs is written whole into a
//! folder of its own, `OUT/.versions/<id>/<n>/`, and `OUT/<id>` is a symlink to it that is
//! replaced by one `rename` (the commit). A reader going through `OUT/<id>/` (the documented
//! paths stay `OUT/<id>/surface.json` etc.) resolves one version folder, so a kill at any
//! moment leaves the old set or the new one, never files of both: unlike renaming the files
//! one by one into a shared folder, where `surface.json` written last marks only the first
//! version as complete.
//!
//! The version folder the link pointed to before stays until the next commit, so that a
//! reader that resolved it just before the switch can still open its files.
//!
//! Ids of files in subfolders (`scans/ear`, recursive watching) publish as
//! `OUT/scans/ear`, a link in the real folder `OUT/scans`, to `OUT/.versions/scans%ear/<n>`:
//! the version store is flat (`%` never survives id sanitising), so one id's versions never
//! sit inside another's. A patch `scans` (from `scans.ply`) and the folder `scans/` cannot
//! both have outputs: whichever comes second is refused as a collision.

use crate::io::{write_atomic_group, IoError};
use std::path::{Path, PathBuf};

/// Under OUT; its leading dot keeps it apart from patch ids (they never start with one).
pub(crate) const VERSIONS: &str = ".versions";
/// A pre-symlink `OUT/<id>` folder is moved here before the first commit replaces it.
const LEGACY: &str = "legacy";

/// A step of publishing, for tests that stop the sequence between any two of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Step {
    VersionFolderMade,
    FilesWritten,
    LinkMade,
    LegacyMovedAside,
    Committed,
    OldVersionsRemoved,
}

#[derive(Debug, thiserror::Error)]
pub(crate) enum PublishError {
    #[error("{path}: {source}")]
    Fs {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Write(#[from] IoError),
    /// The id's folder is taken by another patch's outputs (`scans` and `scans/ear`).
    #[error(
        "{path} holds the outputs of another patch (a patch and a subfolder of the same name)"
    )]
    Collision { path: String },
    /// Only from tests: the checkpoint asked to stop here, as a kill would.
    #[error("stopped after {0:?}")]
    Stopped(Step),
}

fn fs_err(path: &Path) -> impl FnOnce(std::io::Error) -> PublishError + '_ {
    move |source| PublishError::Fs {
        path: path.display().to_string(),
        source,
    }
}

/// The numbered version folders under `base`, in ascending order.
fn versions(base: &Path) -> Vec<u64> {
    let mut v: Vec<u64> = std::fs::read_dir(base)
        .map(|d| {
            d.flatten()
                .filter_map(|e| e.file_name().to_str()?.parse().ok())
                .collect()
        })
        .unwrap_or_default();
    v.sort_unstable();
    v
}

fn link_temp(out: &Path, id: &str) -> PathBuf {
    out.join(format!(".trispline-{}.link.tmp", flat(id)))
}

/// The version store's name of an id: one path component.
pub(crate) fn flat(id: &str) -> String {
    id.replace('/', "%")
}

/// Makes the real folders `OUT/<a>/<b>/..` that hold the link of a nested id; refuses when
/// one of them is another patch's link or outputs.
fn parent_folders(out: &Path, id: &str) -> Result<(), PublishError> {
    let mut dir = out.to_path_buf();
    let parts: Vec<&str> = id.split('/').collect();
    for part in &parts[..parts.len() - 1] {
        dir.push(part);
        match std::fs::symlink_metadata(&dir) {
            Ok(m) if m.is_dir() && !dir.join("surface.json").exists() => {}
            Ok(_) => {
                return Err(PublishError::Collision {
                    path: dir.display().to_string(),
                })
            }
            Err(_) => std::fs::create_dir(&dir).map_err(fs_err(&dir))?,
        }
    }
    Ok(())
}

/// Whether a real folder at a patch's place holds other patches' outputs (links or
/// folders) rather than this patch's own files of before the links.
fn holds_other_patches(folder: &Path) -> bool {
    std::fs::read_dir(folder).is_ok_and(|entries| {
        entries
            .flatten()
            .any(|e| e.file_type().is_ok_and(|t| t.is_symlink() || t.is_dir()))
    })
}

/// Writes `files` as the new version of `id` and switches `OUT/<id>` to it. `checkpoint`
/// is asked after every step whether to go on (production: always).
pub(crate) fn publish(
    out: &Path,
    id: &str,
    files: &[(&str, &[u8])],
    checkpoint: &mut dyn FnMut(Step) -> bool,
) -> Result<(), PublishError> {
    let mut step = |s: Step| {
        if checkpoint(s) {
            Ok(())
        } else {
            Err(PublishError::Stopped(s))
        }
    };
    let public = out.join(id);
    parent_folders(out, id)?;
    if std::fs::symlink_metadata(&public).is_ok_and(|m| m.is_dir()) && holds_other_patches(&public)
    {
        return Err(PublishError::Collision {
            path: public.display().to_string(),
        });
    }
    let base = out.join(VERSIONS).join(flat(id));
    std::fs::create_dir_all(&base).map_err(fs_err(&base))?;
    // Numbers only grow, and start from the clock (microseconds) so that a number is not
    // given out again after start-up repair removed a folder a kill left half-written: a
    // name then always means one set of files.
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64);
    let n = versions(&base).last().map_or(now, |last| now.max(last + 1));
    let dir = base.join(n.to_string());
    std::fs::create_dir(&dir).map_err(fs_err(&dir))?;
    step(Step::VersionFolderMade)?;
    write_atomic_group(&dir, files)?;
    step(Step::FilesWritten)?;
    let temp = link_temp(out, id);
    let _ = std::fs::remove_file(&temp);
    // Relative to the folder the link ends up in.
    let up: PathBuf = id.matches('/').map(|_| "..").collect();
    let target = up.join(VERSIONS).join(flat(id)).join(n.to_string());
    std::os::unix::fs::symlink(&target, &temp).map_err(fs_err(&temp))?;
    step(Step::LinkMade)?;
    let before = std::fs::read_link(&public).ok();
    let is_folder = std::fs::symlink_metadata(&public).is_ok_and(|m| m.is_dir());
    if is_folder {
        // A folder cannot be replaced by a rename; moved aside, it is out of reach for a
        // moment (a reader sees no outputs, not mixed ones) and restored at start-up if a
        // kill lands here.
        let aside = base.join(LEGACY);
        let _ = std::fs::remove_dir_all(&aside);
        std::fs::rename(&public, &aside).map_err(fs_err(&public))?;
        step(Step::LegacyMovedAside)?;
    }
    std::fs::rename(&temp, &public).map_err(fs_err(&public))?;
    std::fs::File::open(out)
        .and_then(|d| d.sync_all())
        .map_err(fs_err(out))?;
    step(Step::Committed)?;
    let keep_previous = before
        .as_ref()
        .and_then(|b| b.file_name())
        .and_then(|n| n.to_str())
        .and_then(|n| n.parse::<u64>().ok());
    remove_old_versions(&base, n, keep_previous);
    step(Step::OldVersionsRemoved)?;
    Ok(())
}

/// Takes `id`'s outputs down: `OUT/<id>` goes in one `unlink` (a reader sees the whole set
/// or none), then its version folders. For an object whose scans are all gone: its surface
/// describes data that no longer exists. False when there was nothing to take down.
pub(crate) fn unpublish(out: &Path, id: &str) -> Result<bool, PublishError> {
    let public = out.join(id);
    let linked = std::fs::symlink_metadata(&public).is_ok_and(|m| m.file_type().is_symlink());
    if linked {
        std::fs::remove_file(&public).map_err(fs_err(&public))?;
        std::fs::File::open(out)
            .and_then(|d| d.sync_all())
            .map_err(fs_err(out))?;
    }
    let base = out.join(VERSIONS).join(flat(id));
    match std::fs::remove_dir_all(&base) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(linked),
        Err(e) => Err(fs_err(&base)(e)),
    }
}

fn remove_old_versions(base: &Path, current: u64, previous: Option<u64>) {
    let Ok(entries) = std::fs::read_dir(base) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let number = name.to_str().and_then(|n| n.parse::<u64>().ok());
        if number == Some(current) || (number.is_some() && number == previous) {
            continue;
        }
        if let Err(err) = std::fs::remove_dir_all(e.path()) {
            tracing::warn!(error = %err, path = %e.path().display(), "cannot remove an old output version");
        }
    }
}

/// At start-up: finishes or undoes what a kill interrupted. A link that was made but not
/// committed is removed; a legacy folder moved aside but not replaced is moved back; version
/// folders nothing points to (half-written ones) are removed.
pub(crate) fn repair(out: &Path) {
    let Ok(entries) = std::fs::read_dir(out) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        if name.starts_with(".trispline-") && name.ends_with(".link.tmp") {
            let _ = std::fs::remove_file(e.path());
        }
    }
    let Ok(bases) = std::fs::read_dir(out.join(VERSIONS)) else {
        return;
    };
    for base in bases.flatten() {
        let id = base.file_name().to_string_lossy().replace('%', "/");
        let public = out.join(&id);
        let aside = base.path().join(LEGACY);
        if std::fs::symlink_metadata(&public).is_err() && aside.is_dir() {
            if let Err(err) = std::fs::rename(&aside, &public) {
                tracing::warn!(error = %err, path = %public.display(), "cannot restore outputs");
            }
            continue;
        }
        let current = std::fs::read_link(&public)
            .ok()
            .and_then(|t| t.file_name()?.to_str()?.parse::<u64>().ok());
        if let Some(current) = current {
            remove_old_versions(&base.path(), current, None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [Step; 6] = [
        Step::VersionFolderMade,
        Step::FilesWritten,
        Step::LinkMade,
        Step::LegacyMovedAside,
        Step::Committed,
        Step::OldVersionsRemoved,
    ];

    fn set(tag: &str) -> Vec<(String, Vec<u8>)> {
        ["surface.glb", "report.json", "surface.json"]
            .iter()
            .map(|n| (n.to_string(), format!("{tag}:{n}").into_bytes()))
            .collect()
    }

    fn publish_set(out: &Path, tag: &str, stop: Option<Step>) -> Result<(), PublishError> {
        let files = set(tag);
        let refs: Vec<(&str, &[u8])> = files
            .iter()
            .map(|(n, b)| (n.as_str(), b.as_slice()))
            .collect();
        publish(out, "p", &refs, &mut |s| Some(s) != stop)
    }

    /// The tag of the one version every output file through `OUT/p/` comes from; panics
    /// on a mixed set. `None` when there are no outputs.
    fn visible(out: &Path) -> Option<String> {
        let dir = out.join("p");
        let tags: Vec<String> = ["surface.glb", "report.json", "surface.json"]
            .iter()
            .filter_map(|n| std::fs::read_to_string(dir.join(n)).ok())
            .map(|c| c.split(':').next().unwrap_or("").to_string())
            .collect();
        if tags.is_empty() {
            return None;
        }
        assert_eq!(tags.len(), 3, "a partial set: {tags:?}");
        assert!(tags.iter().all(|t| *t == tags[0]), "a mixed set: {tags:?}");
        Some(tags[0].clone())
    }

    /// Stops the publishing of version B after every step, from a committed version A in
    /// both layouts (symlinked, and the pre-symlink plain folder): a reader sees A or B whole
    /// (or, only in the instant the plain folder is moved aside, nothing), start-up repair
    /// restores A where B was not committed, and the next version publishes cleanly.
    #[test]
    fn a_stop_between_any_two_steps_never_shows_a_mixed_set() {
        for legacy in [false, true] {
            for stop in ALL {
                let tmp = tempfile::tempdir().expect("tmp");
                let out = tmp.path();
                if legacy {
                    std::fs::create_dir(out.join("p")).expect("mkdir");
                    for (n, b) in set("A") {
                        std::fs::write(out.join("p").join(n), b).expect("write");
                    }
                } else {
                    publish_set(out, "A", None).expect("publishes A");
                }
                let case = format!("legacy {legacy}, stopped after {stop:?}");
                let r = publish_set(out, "B", Some(stop));
                if stop == Step::LegacyMovedAside && !legacy {
                    r.expect("no such step without a plain folder");
                } else {
                    assert!(matches!(r, Err(PublishError::Stopped(_))), "{case}");
                }
                let seen = visible(out);
                let committed = matches!(stop, Step::Committed | Step::OldVersionsRemoved)
                    || (stop == Step::LegacyMovedAside && !legacy);
                if committed {
                    assert_eq!(seen.as_deref(), Some("B"), "{case}");
                } else if stop == Step::LegacyMovedAside {
                    assert_eq!(seen, None, "{case}");
                } else {
                    assert_eq!(seen.as_deref(), Some("A"), "{case}");
                }
                repair(out);
                let want = if committed { "B" } else { "A" };
                assert_eq!(visible(out).as_deref(), Some(want), "{case}: after repair");
                assert!(
                    !link_temp(out, "p").exists()
                        && std::fs::symlink_metadata(link_temp(out, "p")).is_err(),
                    "{case}"
                );
                publish_set(out, "C", None).expect("publishes C");
                assert_eq!(visible(out).as_deref(), Some("C"), "{case}");
                // The current and at most the previous version are kept.
                let kept = std::fs::read_dir(out.join(VERSIONS).join("p"))
                    .expect("versions")
                    .count();
                assert!(kept <= 2, "{case}: {kept} version folders");
            }
        }
    }
}
