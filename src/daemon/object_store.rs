//! Objects fed through the pipe (`{"object": OBJ, "patch": SCAN, ...}`): the daemon keeps
//! their scans in a folder of its own, `STATE/objects/<object>/`, laid out as an object
//! folder of the watch folder would be (`<scan>.<ext>`, and `<scan>.xf` when the record
//! gave a transform), so that one fit (`object_job`) serves both, and a start queues every
//! stored object again (`stored_objects`). Only the writer thread calls this (it alone changes the state folder).

use super::scheduler::{Arrival, Input, VersionKey};
use crate::io::{write_atomic, Format};
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

/// A scan for an object, as a pipe record brought it.
pub(crate) struct ObjectScan {
    /// The object's id (sanitised).
    pub object: String,
    /// The scan: its id is the arrival's id; its bytes are inline or in a confined file.
    pub scan: Arrival,
    /// Row-major 4x4 into the object's frame, checked to be rigid; `None`: the identity.
    pub transform: Option<[f64; 16]>,
    /// `daemon.max_file_bytes`: a path record's file over it is refused unread.
    pub max_bytes: u64,
}

/// A record's `"object"` (sanitised) and its `"transform"`, when it is a scan of one.
pub(crate) type RecordObject = Option<(String, Option<[f64; 16]>)>;

/// The record's `"object"` and `"transform"`: `Ok(None)` without an object; an error for
/// an object that leaves no id, a transform without an object, or a transform that is not
/// 16 numbers of a rigid motion (never taken as the identity).
pub(crate) fn record_object(json: &serde_json::Value) -> Result<RecordObject, String> {
    let transform = json.get("transform");
    let Some(raw) = json.get("object") else {
        return match transform {
            Some(_) => Err("\"transform\" without \"object\"".into()),
            None => Ok(None),
        };
    };
    let id = raw
        .as_str()
        .and_then(super::ids::sanitize_id)
        .ok_or_else(|| format!("\"object\" {raw} leaves no usable id"))?;
    let Some(t) = transform else {
        return Ok(Some((id, None)));
    };
    let numbers: Option<Vec<f64>> = t
        .as_array()
        .map(|a| a.iter().map(serde_json::Value::as_f64).collect())
        .unwrap_or(None);
    let numbers = numbers.filter(|v| v.len() == 16).ok_or_else(|| {
        format!("\"transform\" must be 16 numbers (a 4x4 matrix row by row), got {t}")
    })?;
    crate::mesh::rigid::RigidTransform::from_row_major(&numbers)
        .map_err(|e| format!("\"transform\" is no rigid motion: {e}"))?;
    let mut m = [0.0; 16];
    m.copy_from_slice(&numbers);
    Ok(Some((id, Some(m))))
}

/// The extension of the scan's format: the file's own, or the inline format's.
fn extension(a: &Arrival) -> Option<String> {
    match &a.input {
        Input::File(p) => p.extension().map(|e| e.to_string_lossy().to_lowercase()),
        // An inline record's version name ends in the extension its "format" named.
        Input::Inline { .. } => Path::new(&a.version)
            .extension()
            .map(|e| e.to_string_lossy().to_lowercase()),
        Input::Object(_) => None,
    }
}

/// Writes the scan (and its `.xf`, or removes a stale one) into the object's folder under
/// `objects` and returns the arrival that refits the object. The mesh is written first and
/// the scan's other versions removed last, so a failed write never loses the scan's
/// previous bytes (for a pipe record, the only copy).
pub(crate) fn store_scan(objects: &Path, s: &ObjectScan) -> Result<Arrival, String> {
    let folder = objects.join(super::publish::flat(&s.object));
    let ext = extension(&s.scan).ok_or("the scan has no mesh extension")?;
    if Format::from_extension(&ext).is_none() {
        return Err(format!(
            "\".{ext}\" is not a mesh format ({})",
            Format::READABLE
        ));
    }
    let bytes = match &s.scan.input {
        Input::Inline { data, .. } => data.to_vec(),
        Input::File(p) => read_limited(p, s.max_bytes)?,
        Input::Object(_) => return Err("an object is no scan".into()),
    };
    std::fs::create_dir_all(&folder)
        .map_err(|e| format!("cannot create {}: {e}", folder.display()))?;
    // Other versions of the scan (another extension) would compete with this one.
    let target = folder.join(format!("{}.{ext}", s.scan.id));
    let stale: Vec<PathBuf> = std::fs::read_dir(&folder)
        .map_err(|e| e.to_string())?
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            super::ids::patch_id(p).as_deref() == Some(s.scan.id.as_str())
                && p.extension().is_some_and(|e| e != "xf")
                && *p != target
        })
        .collect();
    // The transform goes down before the mesh: a fit of the object already running reads
    // the folder whenever it likes, and must never see the new mesh without its transform
    // (it would publish the scan misplaced). If the mesh then cannot be written, the
    // previous transform is put back, so the scan stays as it was.
    let xf = folder.join(format!("{}.xf", s.scan.id));
    let previous_xf = std::fs::read(&xf).ok();
    set_transform(&xf, s.transform.as_ref())?;
    if let Err(e) = write_atomic(&target, &bytes) {
        let restored = match &previous_xf {
            Some(old) => write_atomic(&xf, old).map_err(|e| e.to_string()),
            None => set_transform(&xf, None),
        };
        return Err(match restored {
            Ok(()) => e.to_string(),
            Err(r) => format!("{e}; and the previous transform could not be restored: {r}"),
        });
    }
    for p in &stale {
        std::fs::remove_file(p).map_err(|e| format!("cannot remove {}: {e}", p.display()))?;
    }
    let version = format!("{}.{ext}", s.scan.id);
    let label = format!("{} (object {})", s.scan.label, s.object);
    Ok(object_arrival(s.object.clone(), folder, version, label))
}

/// Writes a scan's rigid transform as Stanford's `.xf` (four rows of four), or removes the
/// sidecar when the record carries none.
fn set_transform(xf: &Path, transform: Option<&[f64; 16]>) -> Result<(), String> {
    match transform {
        Some(m) => {
            let rows: Vec<String> = m
                .chunks(4)
                .map(|r| {
                    r.iter()
                        .map(|v| format!("{v:e}"))
                        .collect::<Vec<_>>()
                        .join(" ")
                })
                .collect();
            write_atomic(xf, format!("{}\n", rows.join("\n")).as_bytes()).map_err(|e| e.to_string())
        }
        None => match std::fs::remove_file(xf) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(format!("cannot remove {}: {e}", xf.display())),
        },
    }
}

/// A path record's file, refused over `max_bytes` before it is read.
fn read_limited(path: &Path, max_bytes: u64) -> Result<Vec<u8>, String> {
    let size = std::fs::metadata(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?
        .len();
    if size > max_bytes {
        return Err(format!(
            "{} has {size} bytes, over daemon.max_file_bytes = {max_bytes}",
            path.display()
        ));
    }
    std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))
}

/// A fit of object `id` from its folder as it is when the fit runs; `version` names what
/// changed. Each is newer than the last: the scheduler keeps only the newest waiting one.
pub(crate) fn object_arrival(
    id: String,
    folder: PathBuf,
    version: String,
    label: String,
) -> Arrival {
    Arrival {
        id,
        label,
        input: Input::Object(folder),
        key: VersionKey {
            time: SystemTime::now(),
            tie: version.clone(),
        },
        version,
        detected: Instant::now(),
    }
}

/// Why an input may not have outputs under its id, when an object holds that id. Objects
/// and patches share `OUT/<id>/` and the state store, so one id is one thing: an object
/// folder of the watch folder (with `object.folders`) holds its id against everything
/// else, an object of pipe records (kept under `objects`) against patches. A patch named
/// like an object, or a pipe object named like an object folder, is refused by this reason.
pub(crate) fn id_held_by_object(
    id: &str,
    input: &Input,
    watch_dir: &Path,
    objects: &Path,
    folders: bool,
) -> Option<String> {
    if id.contains('/') {
        // Object ids are single names; a nested patch id is no object's.
        return None;
    }
    let folder = watch_dir.join(id);
    let held_by_folder = folders && folder.is_dir();
    match input {
        Input::Object(f) if f.starts_with(objects) && held_by_folder => Some(format!(
            "{} is an object folder of the same name; its scans are the object \"{id}\"",
            folder.display()
        )),
        Input::Object(_) => None,
        Input::File(_) | Input::Inline { .. } if held_by_folder => Some(format!(
            "patch \"{id}\" has the name of the object folder {}; rename the file",
            folder.display()
        )),
        Input::File(_) | Input::Inline { .. } => objects.join(id).is_dir().then(|| {
            format!("patch \"{id}\" has the name of an object of pipe records; rename it")
        }),
    }
}

/// A refit of every object kept under `objects`: a scan stored just before a stop may not
/// have been fitted yet (the fit is queued after the store). An object whose scans did not
/// change since its last fit is found unchanged by its content hash and not refitted.
pub(crate) fn stored_objects(objects: &Path) -> Vec<Arrival> {
    let Ok(entries) = std::fs::read_dir(objects) else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().to_string();
            // Only folders this store made: their names are sanitised ids.
            (super::ids::sanitize_id(&name).as_deref() == Some(name.as_str())).then(|| {
                let label = format!("{} (stored object)", e.path().display());
                object_arrival(name, e.path(), "restart".into(), label)
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::Format;
    use std::sync::Arc;

    fn inline(id: &str, ext: &str, bytes: &[u8]) -> Arrival {
        Arrival {
            id: id.into(),
            input: Input::Inline {
                data: Arc::new(bytes.to_vec()),
                format: Format::from_extension(ext).expect("format"),
            },
            key: VersionKey {
                time: SystemTime::now(),
                tie: String::new(),
            },
            version: format!("{id}@pipe-1.{ext}"),
            label: "pipe:test#1".into(),
            detected: Instant::now(),
        }
    }

    /// A quarter turn about z, as a pipe record's `"transform"` gives it.
    const TURN: [f64; 16] = [
        0., -1., 0., 0., 1., 0., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
    ];

    /// Scan `s` of object `o`, sent inline with the transform `TURN`.
    fn turned_scan(ext: &str, bytes: &[u8]) -> ObjectScan {
        ObjectScan {
            object: "o".into(),
            scan: inline("s", ext, bytes),
            transform: Some(TURN),
            max_bytes: u64::MAX,
        }
    }

    #[test]
    fn a_stored_scan_replaces_its_other_versions_and_its_transform() {
        let tmp = tempfile::tempdir().expect("tmp");
        let first = turned_scan("obj", b"v 0 0 0\n");
        let a = store_scan(tmp.path(), &first).expect("stored");
        let folder = tmp.path().join("o");
        assert!(matches!(&a.input, Input::Object(f) if *f == folder));
        assert_eq!(a.id, "o");
        let xf = std::fs::read_to_string(folder.join("s.xf")).expect("xf");
        let read = crate::io::registration::parse_xf(&xf, "s.xf").expect("rigid");
        assert_eq!(read.to_row_major(), TURN);
        // A new version in another format without a transform: the old file and the .xf go.
        let second = ObjectScan {
            object: "o".into(),
            scan: inline("s", "ply", b"ply\n"),
            transform: None,
            max_bytes: u64::MAX,
        };
        store_scan(tmp.path(), &second).expect("stored");
        let mut names: Vec<String> = std::fs::read_dir(&folder)
            .expect("list")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .collect();
        names.sort();
        assert_eq!(names, ["s.ply"]);
    }

    fn file(id: &str, path: &Path) -> Arrival {
        Arrival {
            input: Input::File(path.to_path_buf()),
            ..inline(id, "ply", b"")
        }
    }

    #[test]
    fn a_path_record_that_is_no_mesh_or_too_big_leaves_the_stored_scan_alone() {
        let tmp = tempfile::tempdir().expect("tmp");
        let objects = tmp.path().join("objects");
        let good = ObjectScan {
            object: "o".into(),
            scan: inline("s", "ply", b"ply\n"),
            transform: None,
            max_bytes: u64::MAX,
        };
        store_scan(&objects, &good).expect("stored");
        let text = tmp.path().join("notes.txt");
        std::fs::write(&text, b"not a mesh").expect("write");
        let no_mesh = ObjectScan {
            scan: file("s", &text),
            ..good
        };
        let refused = store_scan(&objects, &no_mesh).expect_err("a .txt is no scan");
        assert!(refused.contains("not a mesh format"), "{refused}");
        let big = tmp.path().join("big.obj");
        std::fs::write(&big, vec![b'#'; 100]).expect("write");
        let too_big = ObjectScan {
            scan: file("s", &big),
            max_bytes: 99,
            ..no_mesh
        };
        let refused = store_scan(&objects, &too_big).expect_err("over the limit");
        assert!(refused.contains("max_file_bytes"), "{refused}");
        let kept = std::fs::read(objects.join("o/s.ply")).expect("the stored scan stays");
        assert_eq!(kept, b"ply\n");
        // The store is found again at a start, under its sanitised name only.
        std::fs::create_dir_all(objects.join("not clean")).expect("mkdir");
        let resumed = stored_objects(&objects);
        assert_eq!(resumed.len(), 1);
        assert_eq!(resumed[0].id, "o");
        assert!(matches!(&resumed[0].input, Input::Object(f) if *f == objects.join("o")));
    }

    #[test]
    fn a_mesh_that_cannot_be_written_leaves_the_previous_transform() {
        let tmp = tempfile::tempdir().expect("tmp");
        let first = turned_scan("ply", b"ply\n");
        store_scan(tmp.path(), &first).expect("stored");
        let folder = tmp.path().join("o");
        let before = std::fs::read(folder.join("s.xf")).expect("xf");
        // A folder where the new version's file would go: its write fails after the
        // transform was already replaced.
        std::fs::create_dir_all(folder.join("s.obj").join("busy")).expect("mkdir");
        let blocked = ObjectScan {
            scan: inline("s", "obj", b"v 0 0 0\n"),
            transform: None,
            ..first
        };
        store_scan(tmp.path(), &blocked).expect_err("the mesh cannot be written");
        assert_eq!(std::fs::read(folder.join("s.xf")).expect("xf back"), before);
        assert_eq!(std::fs::read(folder.join("s.ply")).expect("kept"), b"ply\n");
    }
}
