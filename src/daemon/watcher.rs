//! The folder source. Native: inotify through `notify`; a rename into the folder or a close
//! after writing counts as arrival at once, and a file seen being written (created or
//! modified under the watch) waits for its close, however long the writer pauses. The
//! settle time (size and mtime stable) is only for files that predate the watch, files
//! found by a rescan after an overflow, and polling mode, and even then a file some process
//! still holds open for writing is not taken (`open_files`, where the OS can tell). Both
//! modes rescan the whole folder at start-up; native also on overflow. Arrivals go to the
//! scheduler over an unbounded channel: this thread never waits for fitting.

use super::config::WatcherKind;
use super::ids::partial_name;
use super::kinds::{rejection_kind, Cause};
use super::messages::{ignored, relative_patch_id, Msg, Source};
use super::open_files::open_for_writing;
use super::reload::ConfigCell;
use super::scheduler::{Arrival, Input, VersionKey};
use super::writer::{Keep, WriterMsg};
use crossbeam_channel::{RecvTimeoutError, Sender};
use notify::event::{AccessKind, AccessMode, ModifyKind, RenameMode};
use notify::{EventKind, RecursiveMode, Watcher};
use std::collections::HashMap;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

/// What identifies one state of a file: a new inode (rename-into) or new size or mtime is a
/// new version.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Stamp {
    size: u64,
    mtime: SystemTime,
    ino: u64,
}

fn stamp(path: &Path) -> Option<Stamp> {
    let m = std::fs::metadata(path).ok()?;
    m.is_file().then(|| Stamp {
        size: m.len(),
        mtime: m.modified().unwrap_or(SystemTime::UNIX_EPOCH),
        ino: m.ino(),
    })
}

pub struct FolderWatcher {
    pub dir: PathBuf,
    pub cell: Arc<ConfigCell>,
    pub kind: WatcherKind,
    pub once: bool,
    pub tx: Sender<Msg>,
    pub writer: Sender<WriterMsg>,
    pub stop: Arc<AtomicBool>,
    /// Told once the watch is in place and the start-up scan is done (readiness).
    pub ready: Sender<()>,
    /// Subfolders are watched too (`daemon.recursive`).
    pub recursive: bool,
    /// Subfolders are objects (`object.folders`): a file that arrives in one, or goes, is
    /// a change of its object, and so are its registration files (`.xf`, `.conf`).
    pub objects: bool,
    /// Canonical folders never descended into (OUT, the state folder, quarantine when they
    /// lie inside the watch folder: their files are outputs, not inputs).
    pub exclude: Vec<PathBuf>,
}

/// Subfolders deeper than this are not walked (a guard, not a limit anyone should meet).
const MAX_DEPTH: usize = 32;

/// A file seen but not yet complete.
struct Waiting {
    stamp: Stamp,
    /// Since when `stamp` has been unchanged.
    since: Instant,
    /// Native mode saw it being written: it is complete on its close (or, if that event was
    /// lost, once no process is seen holding it open for writing and the OS can tell).
    written: bool,
}

struct Tracker {
    /// Files seen but not yet complete.
    settling: HashMap<PathBuf, Waiting>,
    /// The stamp each file had when handed on, so that a rescan does not repeat it.
    emitted: HashMap<PathBuf, Stamp>,
    batch: Vec<Arrival>,
    /// Entries left alone and why, so that each is reported once (again only if the reason
    /// changes or the entry comes back after going away).
    skipped: HashMap<PathBuf, Skip>,
}

/// Why the watcher leaves an entry alone.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Skip {
    NonUtf8Name,
    SymlinkLoop,
    DanglingSymlink,
    Directory,
    Fifo,
    Device,
    Socket,
    /// Not a regular file for another reason, or its metadata cannot be read.
    Unreadable,
    /// A name with no mesh extension: reported at debug level only (a README beside the
    /// scans is normal).
    NotAMesh,
}

impl Skip {
    fn kind(self) -> &'static str {
        match self {
            Skip::NonUtf8Name => "non_utf8_name",
            Skip::SymlinkLoop => "symlink_loop",
            Skip::DanglingSymlink => "dangling_symlink",
            Skip::Directory => "directory",
            Skip::Fifo => "fifo",
            Skip::Device => "device",
            Skip::Socket => "socket",
            Skip::Unreadable => "unreadable",
            Skip::NotAMesh => "not_a_mesh",
        }
    }
}

/// Why an entry of the watch folder is not an input, or `None` when it is one (or is a
/// temporary name that will be renamed into one).
pub(crate) fn skip_reason(path: &Path) -> Option<Skip> {
    use std::os::unix::fs::FileTypeExt;
    let name = path.file_name()?;
    let Some(name) = name.to_str() else {
        return Some(Skip::NonUtf8Name);
    };
    if name.starts_with('.') || name.ends_with(".tmp") || name.ends_with(".part") {
        return None;
    }
    let link = std::fs::symlink_metadata(path).ok()?;
    // A subfolder is reported whatever its name (without --recursive its files are not
    // taken, and that should not pass in silence).
    if link.is_dir() {
        return Some(Skip::Directory);
    }
    if ignored(path) {
        return Some(Skip::NotAMesh);
    }
    let meta = if link.file_type().is_symlink() {
        match std::fs::metadata(path) {
            Ok(m) => m,
            // ELOOP: the standard library has no ErrorKind for it on every toolchain.
            Err(e) if e.raw_os_error() == Some(40) => return Some(Skip::SymlinkLoop),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Some(Skip::DanglingSymlink)
            }
            Err(_) => return Some(Skip::Unreadable),
        }
    } else {
        link
    };
    let t = meta.file_type();
    match () {
        _ if t.is_file() => None,
        _ if t.is_dir() => Some(Skip::Directory),
        _ if t.is_fifo() => Some(Skip::Fifo),
        _ if t.is_block_device() || t.is_char_device() => Some(Skip::Device),
        _ if t.is_socket() => Some(Skip::Socket),
        _ => Some(Skip::Unreadable),
    }
}

impl FolderWatcher {
    pub fn run(self) {
        let mut t = Tracker {
            settling: HashMap::new(),
            emitted: HashMap::new(),
            batch: Vec::new(),
            skipped: HashMap::new(),
        };
        // Keep the watcher alive for the whole loop; it is created before the first scan so
        // that nothing arriving in between is missed.
        let (ntx, nrx) = crossbeam_channel::unbounded();
        let native = (self.kind == WatcherKind::Native && !self.once)
            .then(|| {
                let mut w = notify::recommended_watcher(move |ev| {
                    let _ = ntx.send(ev);
                })?;
                let mode = match self.recursive {
                    true => RecursiveMode::Recursive,
                    false => RecursiveMode::NonRecursive,
                };
                w.watch(&self.dir, mode)?;
                Ok::<_, notify::Error>(w)
            })
            .and_then(|r| {
                r.map_err(|e| tracing::warn!(error = %e, "native watching unavailable; polling"))
                    .ok()
            });
        tracing::info!(dir = %self.dir.display(), native = native.is_some(), "watching");
        self.scan(&mut t);
        let _ = self.ready.send(());
        loop {
            let cfg = self.cell.get();
            let settle = Duration::from_millis(cfg.daemon.settle_ms);
            let poll = Duration::from_millis(cfg.daemon.poll_interval_ms);
            if native.is_some() {
                // Only files that neither closed nor were renamed in need the settle clock.
                let floor = Duration::from_millis(10);
                let tick = (settle / 4).clamp(floor, poll.max(floor));
                match nrx.recv_timeout(tick) {
                    Ok(ev) => {
                        self.native_event(&mut t, ev);
                        while let Ok(ev) = nrx.try_recv() {
                            self.native_event(&mut t, ev);
                        }
                    }
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => break,
                }
            } else {
                std::thread::sleep(poll);
                self.scan(&mut t);
            }
            self.settle(&mut t, settle);
            self.flush(&mut t);
            if self.stop.load(Ordering::Relaxed) || (self.once && t.settling.is_empty()) {
                break;
            }
        }
        drop(native);
        let _ = self.tx.send(Msg::SourceDone(Source::Folder));
    }

    fn native_event(&self, t: &mut Tracker, ev: notify::Result<notify::Event>) {
        let ev = match ev {
            Ok(ev) => ev,
            Err(e) => {
                tracing::warn!(error = %e, "watch error; rescanning");
                return self.scan(t);
            }
        };
        if ev.need_rescan() {
            tracing::info!("event queue overflowed; rescanning");
            return self.scan(t);
        }
        match ev.kind {
            EventKind::Access(AccessKind::Close(AccessMode::Write))
            | EventKind::Modify(ModifyKind::Name(RenameMode::To)) => {
                if let Some(p) = ev.paths.first() {
                    self.complete(t, p);
                }
            }
            EventKind::Modify(ModifyKind::Name(RenameMode::Both)) => {
                if let Some(p) = ev.paths.get(1) {
                    self.complete(t, p);
                }
            }
            EventKind::Modify(ModifyKind::Name(RenameMode::From)) | EventKind::Remove(_) => {
                for p in &ev.paths {
                    let went: Vec<PathBuf> = t
                        .emitted
                        .keys()
                        .filter(|q| q.starts_with(p))
                        .cloned()
                        .collect();
                    self.went(t, &went);
                    // A folder that went takes what was seen in it along.
                    t.settling.retain(|q, _| !q.starts_with(p));
                    t.emitted.retain(|q, _| !q.starts_with(p));
                    t.skipped.retain(|q, _| !q.starts_with(p));
                }
            }
            EventKind::Create(_) | EventKind::Modify(ModifyKind::Data(_) | ModifyKind::Any) => {
                for p in &ev.paths {
                    if self.is_subfolder(p) {
                        // Moved or copied in whole: its files raise no events of their own.
                        self.scan_dir(t, p, Instant::now(), &mut Default::default(), 1);
                    } else {
                        self.seen(t, p, Instant::now(), true);
                    }
                }
            }
            EventKind::Modify(_) => {
                for p in &ev.paths {
                    self.seen(t, p, Instant::now(), false);
                }
            }
            _ => {}
        }
    }

    /// Whether `path` is an entry this watcher takes: in the watch folder, or with
    /// `recursive` under it, outside the excluded folders and hidden ones.
    fn within(&self, path: &Path) -> bool {
        if !self.recursive {
            return path.parent() == Some(self.dir.as_path());
        }
        let Ok(rel) = path.strip_prefix(&self.dir) else {
            return false;
        };
        let hidden = rel
            .parent()
            .into_iter()
            .flat_map(Path::components)
            .any(|c| c.as_os_str().to_string_lossy().starts_with('.'));
        !hidden && !rel.as_os_str().is_empty() && !self.exclude.iter().any(|x| path.starts_with(x))
    }

    /// A real (not symlinked) subfolder that recursive watching walks.
    fn is_subfolder(&self, path: &Path) -> bool {
        self.recursive
            && self.within(path)
            && !path
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'))
            && std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir())
    }

    /// A file that is known to be complete (renamed in, or closed after writing).
    fn complete(&self, t: &mut Tracker, path: &Path) {
        if self.is_subfolder(path) {
            self.scan_dir(t, path, Instant::now(), &mut Default::default(), 1);
            return;
        }
        if !self.within(path) || self.skips(t, path) || !self.takes(path) {
            return;
        }
        t.settling.remove(path);
        if let Some(s) = stamp(path) {
            self.emit(t, path, s);
        }
    }

    /// A file that may still be written: starts or restarts its settle clock; `written`
    /// when the watch saw the write itself (then it waits for the close).
    fn seen(&self, t: &mut Tracker, path: &Path, now: Instant, written: bool) {
        if !self.within(path) || self.skips(t, path) || !self.takes(path) {
            t.settling.remove(path);
            return;
        }
        let Some(s) = stamp(path) else {
            t.settling.remove(path);
            return;
        };
        if t.emitted.get(path) == Some(&s) && !written {
            return;
        }
        match t.settling.get_mut(path) {
            Some(w) => {
                w.written |= written;
                if w.stamp != s {
                    w.stamp = s;
                    w.since = now;
                }
            }
            None => {
                t.settling.insert(
                    path.to_path_buf(),
                    Waiting {
                        stamp: s,
                        since: now,
                        written,
                    },
                );
            }
        }
    }

    fn scan(&self, t: &mut Tracker) {
        let now = Instant::now();
        let mut present = std::collections::HashSet::new();
        if !self.scan_dir(t, &self.dir, now, &mut present, 0) {
            return;
        }
        let went: Vec<PathBuf> = t
            .emitted
            .keys()
            .filter(|p| !present.contains(*p))
            .cloned()
            .collect();
        self.went(t, &went);
        t.emitted.retain(|p, _| present.contains(p));
        t.settling.retain(|p, _| present.contains(p));
        t.skipped.retain(|p, _| present.contains(p));
    }

    /// Looks at every entry of `dir` (and, recursive, of its subfolders); false when `dir`
    /// cannot be listed.
    fn scan_dir(
        &self,
        t: &mut Tracker,
        dir: &Path,
        now: Instant,
        present: &mut std::collections::HashSet<PathBuf>,
        depth: usize,
    ) -> bool {
        let entries = match std::fs::read_dir(dir) {
            Ok(e) => e,
            Err(e) => {
                // The folder may be remounted or recreated; keep trying rather than exit.
                tracing::error!(error = %e, dir = %dir.display(), "cannot list the watch folder");
                return false;
            }
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if depth < MAX_DEPTH && self.is_subfolder(&path) {
                self.scan_dir(t, &path, now, present, depth + 1);
                continue;
            }
            present.insert(path.clone());
            self.seen(t, &path, now, false);
        }
        true
    }

    /// Whether the entry is skipped; reports it the first time (per reason).
    fn skips(&self, t: &mut Tracker, path: &Path) -> bool {
        let taken = |w: &Skip| *w == Skip::NotAMesh && self.takes(path);
        let Some(why) = skip_reason(path).filter(|w| !taken(w)) else {
            t.skipped.remove(path);
            return false;
        };
        if t.skipped.insert(path.to_path_buf(), why) != Some(why) {
            let input = path.display().to_string();
            if why == Skip::NotAMesh {
                tracing::debug!(input, "not a mesh file name; skipped");
            } else if why == Skip::Directory && !self.recursive {
                tracing::warn!(
                    input,
                    kind = why.kind(),
                    "a subfolder: skipped (watch --recursive takes its files)"
                );
                let _ = self.writer.send(WriterMsg::Event(serde_json::json!({
                    "input": input, "status": "skipped", "kind": why.kind(),
                    "reason": "a subfolder; daemon.recursive (watch --recursive) takes its files",
                })));
            } else {
                tracing::warn!(input, kind = why.kind(), "skipped");
                let _ = self.writer.send(WriterMsg::Event(serde_json::json!({
                    "input": input, "status": "skipped", "kind": why.kind(),
                })));
            }
        }
        true
    }

    /// Hands on the files whose stamp stayed the same for the settle time, unless a process
    /// is seen holding one open for writing (its clock then starts again). A file the watch
    /// saw being written is only taken here when the OS can tell that nobody writes it any
    /// more (its close event was lost); otherwise it waits for the close.
    fn settle(&self, t: &mut Tracker, settle: Duration) {
        let now = Instant::now();
        let mut due = Vec::new();
        t.settling.retain(|path, w| match stamp(path) {
            None => false,
            Some(s) => {
                if w.stamp != s {
                    w.stamp = s;
                    w.since = now;
                } else if now.duration_since(w.since) >= settle {
                    due.push(path.clone());
                }
                true
            }
        });
        if due.is_empty() {
            return;
        }
        let refs: Vec<&Path> = due.iter().map(PathBuf::as_path).collect();
        let writers = open_for_writing(&refs);
        for path in due {
            let Some(w) = t.settling.get_mut(&path) else {
                continue;
            };
            let take = match (writers.writing(&path), w.written) {
                (Some(true), _) => false,
                (Some(false), _) => true,
                (None, written) => !written,
            };
            if !take {
                tracing::debug!(input = %path.display(), "still open for writing; waiting");
                w.since = now;
                continue;
            }
            if w.written {
                tracing::info!(input = %path.display(), "no close seen, but no process writes it any more; taken");
            }
            let s = w.stamp;
            t.settling.remove(&path);
            self.emit(t, &path, s);
        }
    }

    fn emit(&self, t: &mut Tracker, path: &Path, s: Stamp) {
        if t.emitted.insert(path.to_path_buf(), s) == Some(s) {
            return;
        }
        if let Some((id, folder)) = self.object_of(path) {
            return self.object_changed(t, id, folder, path);
        }
        let label = path.display().to_string();
        let Some(id) = relative_patch_id(&self.dir, path) else {
            let _ = self.writer.send(WriterMsg::Reject {
                id: String::new(),
                label,
                keep: Keep::Move(path.to_path_buf()),
                kind: rejection_kind(&Cause::NoPatchId),
                reason: "file name gives no usable patch id".into(),
            });
            return;
        };
        let version = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        t.batch.push(Arrival {
            id,
            input: Input::File(path.to_path_buf()),
            key: VersionKey {
                time: s.mtime,
                tie: version.clone(),
            },
            version,
            label,
            detected: Instant::now(),
        });
    }

    /// The object (id and folder) a path in a subfolder belongs to, with `objects`: the
    /// subfolder directly under the watch folder.
    fn object_of(&self, path: &Path) -> Option<(String, PathBuf)> {
        if !self.objects {
            return None;
        }
        let rel = path.strip_prefix(&self.dir).ok()?;
        let mut parts = rel.components();
        let (Some(std::path::Component::Normal(first)), Some(_)) = (parts.next(), parts.next())
        else {
            return None;
        };
        let id = super::messages::sanitize_id(first.to_str()?)?;
        Some((id, self.dir.join(first)))
    }

    /// Whether the watcher hands the file on: meshes, and registration files of objects.
    /// A registration file under a partial name (`.bun045.xf` before its rename) is not
    /// one yet: no scan reads it, and taking it would queue updates of the object that
    /// the rename supersedes.
    fn takes(&self, path: &Path) -> bool {
        let registration = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("xf") || e.eq_ignore_ascii_case("conf"));
        !ignored(path) || (registration && !partial_name(path) && self.object_of(path).is_some())
    }

    /// Files handed on before that are gone: a change of the objects they were in.
    fn went(&self, t: &mut Tracker, paths: &[PathBuf]) {
        for path in paths {
            if let Some((id, folder)) = self.object_of(path) {
                self.object_changed(t, id, folder, path);
            }
        }
    }

    /// Queues a fit of the object `id` from its folder as it is; `path` is what changed.
    fn object_changed(&self, t: &mut Tracker, id: String, folder: PathBuf, path: &Path) {
        let version = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let label = folder.display().to_string();
        t.batch.push(super::object_store::object_arrival(
            id, folder, version, label,
        ));
    }

    /// Sends what one scan or one burst of events found as one message, so the scheduler
    /// coalesces versions before it hands any of them out.
    fn flush(&self, t: &mut Tracker) {
        if !t.batch.is_empty() {
            let _ = self.tx.send(Msg::Arrivals(std::mem::take(&mut t.batch)));
        }
    }
}
