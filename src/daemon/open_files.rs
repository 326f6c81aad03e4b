//! Whether some process still has a file open for writing, where the OS can tell.
//!
//! Linux: every process's `/proc/<pid>/fd/<n>` is a link to the file it has open, and
//! `/proc/<pid>/fdinfo/<n>` gives the open flags (`O_ACCMODE`). Chosen over `fcntl`
//! leases (`F_SETLEASE`/`F_GETLEASE`): taking a lease needs the daemon to own the file (or
//! `CAP_LEASE`), fails as soon as *any* other process has it open (a viewer reading it, too),
//! and makes the writer's next `open` block until the lease is broken, so the check would
//! change what it watches. Reading `/proc` only looks. What it cannot see: other users'
//! processes when the daemon is not root (or `/proc` mounted `hidepid`), and writers on
//! other machines (network filesystems); the answer is then "cannot tell".

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// The answer for a set of files.
#[derive(Debug, Default)]
pub(crate) struct Writers {
    /// Files some visible process holds open for writing.
    pub(crate) open: HashSet<PathBuf>,
    /// False when some process's descriptors could not be read (or there is no `/proc`):
    /// a file not in `open` may still have a writer then.
    pub(crate) complete: bool,
}

impl Writers {
    /// `Some(true)`: a writer holds it; `Some(false)`: certainly none (every process was
    /// seen); `None`: none seen, but the OS could not show every process.
    pub(crate) fn writing(&self, path: &Path) -> Option<bool> {
        if self.open.contains(path) {
            Some(true)
        } else if self.complete {
            Some(false)
        } else {
            None
        }
    }
}

/// Which of `paths` (absolute, symlink-free: the kernel's links are) a process has open for
/// writing. One pass over all processes for all the files, since a pass costs the same for
/// one file or many.
pub(crate) fn open_for_writing(paths: &[&Path]) -> Writers {
    let mut found = Writers {
        open: HashSet::new(),
        complete: true,
    };
    if paths.is_empty() {
        return found;
    }
    let wanted: HashSet<&Path> = paths.iter().copied().collect();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        found.complete = false;
        return found;
    };
    let me = std::process::id().to_string();
    for proc_entry in procs.flatten() {
        let name = proc_entry.file_name();
        let Some(pid) = name
            .to_str()
            .filter(|n| n.bytes().all(|b| b.is_ascii_digit()))
        else {
            continue;
        };
        if pid == me {
            // The daemon's own reads are not writers.
            continue;
        }
        let fd_dir = proc_entry.path().join("fd");
        let fds = match std::fs::read_dir(&fd_dir) {
            Ok(f) => f,
            // The process ended between the listing and now: it holds nothing.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(_) => {
                found.complete = false;
                continue;
            }
        };
        for fd in fds.flatten() {
            let Ok(target) = std::fs::read_link(fd.path()) else {
                continue;
            };
            if !wanted.contains(target.as_path()) {
                continue;
            }
            let info = proc_entry.path().join("fdinfo").join(fd.file_name());
            // Unreadable flags: count it as a writer rather than take a file too early.
            if std::fs::read_to_string(info).map_or(true, |text| flags_write(&text).unwrap_or(true))
            {
                found.open.insert(target);
            }
        }
    }
    found
}

/// Whether the `flags:` line of an fdinfo (octal) opens for writing.
fn flags_write(fdinfo: &str) -> Option<bool> {
    let line = fdinfo.lines().find_map(|l| l.strip_prefix("flags:"))?;
    let flags = u32::from_str_radix(line.trim(), 8).ok()?;
    let mode = flags & libc::O_ACCMODE as u32;
    Some(mode == libc::O_WRONLY as u32 || mode == libc::O_RDWR as u32)
}

/// Whether the file is no longer what was read: another size or mtime than before the
/// read, or another length than the bytes read.
pub(crate) fn still_changing(
    path: &std::path::Path,
    before: (u64, Option<SystemTime>),
    read: usize,
) -> bool {
    match std::fs::metadata(path) {
        Ok(m) => m.len() != before.0 || m.modified().ok() != before.1 || read as u64 != m.len(),
        // Gone or replaced mid-read: whatever was read is not the file any more.
        Err(_) => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fdinfo_flags_say_the_access_mode() {
        assert_eq!(
            flags_write("pos:\t0\nflags:\t0100002\nmnt_id:\t1\n"),
            Some(true)
        );
        assert_eq!(flags_write("pos:\t0\nflags:\t0100001\n"), Some(true));
        assert_eq!(flags_write("pos:\t0\nflags:\t0100000\n"), Some(false));
        assert_eq!(flags_write("pos:\t0\n"), None);
    }

    /// A child process holding the file open for writing is seen; once it exits, not.
    #[test]
    fn a_writer_in_another_process_is_seen_until_it_closes() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = std::fs::canonicalize(dir.path())
            .expect("canonical")
            .join("held.ply");
        std::fs::write(&path, b"ply\n").expect("write");
        let mut child = std::process::Command::new("sh")
            .arg("-c")
            // `exec` so that the process killed below is the one holding the descriptor (a
            // forked `sleep` would inherit it and stay a writer).
            .arg(format!("exec 3>>'{}'; exec sleep 30", path.display()))
            .spawn()
            .expect("sh runs");
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        let mut seen = false;
        while std::time::Instant::now() < deadline && !seen {
            seen = open_for_writing(&[&path]).writing(&path) == Some(true);
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
        assert!(seen, "the shell's write descriptor is visible in /proc");
        assert_ne!(open_for_writing(&[&path]).writing(&path), Some(true));
        // Our own read-only handle is never a writer.
        let _reader = std::fs::File::open(&path).expect("open");
        assert_ne!(open_for_writing(&[&path]).writing(&path), Some(true));
    }
}
