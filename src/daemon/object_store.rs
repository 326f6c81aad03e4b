//! Objects fed through the pipe (`{"object": OBJ, "patch": SCAN, ...}`): the daemon keeps
//! their scans in a folder of its own, `STATE/objects/<object>/`, laid out as an object
//! folder of the watch folder would be (`<scan>.<ext>`, and `<scan>.xf` when the record
//! gave a transform), so that one fit (`object_job`) serves both and a restart finds the
//! scans again. Only the writer thread calls this (it alone changes the state folder).

use super::scheduler::{Arrival, Input, VersionKey};
use crate::io::write_atomic;
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
/// `objects` and returns the arrival that refits the object.
pub(crate) fn store_scan(objects: &Path, s: &ObjectScan) -> Result<Arrival, String> {
    let folder = objects.join(super::publish::flat(&s.object));
    std::fs::create_dir_all(&folder)
        .map_err(|e| format!("cannot create {}: {e}", folder.display()))?;
    let ext = extension(&s.scan).ok_or("the scan has no mesh extension")?;
    let bytes = match &s.scan.input {
        Input::Inline { data, .. } => data.to_vec(),
        Input::File(p) => {
            std::fs::read(p).map_err(|e| format!("cannot read {}: {e}", p.display()))?
        }
        Input::Object(_) => return Err("an object is no scan".into()),
    };
    // Other versions of the scan (another extension) would compete with this one.
    let stale: Vec<PathBuf> = std::fs::read_dir(&folder)
        .map_err(|e| e.to_string())?
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            super::ids::patch_id(p).as_deref() == Some(s.scan.id.as_str())
                && p.extension().is_some_and(|e| e != "xf")
        })
        .collect();
    let xf = folder.join(format!("{}.xf", s.scan.id));
    match &s.transform {
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
            write_atomic(&xf, format!("{}\n", rows.join("\n")).as_bytes())
                .map_err(|e| e.to_string())?;
        }
        None => match std::fs::remove_file(&xf) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(format!("cannot remove {}: {e}", xf.display())),
        },
    }
    let target = folder.join(format!("{}.{ext}", s.scan.id));
    for p in stale.iter().filter(|p| **p != target) {
        std::fs::remove_file(p).map_err(|e| format!("cannot remove {}: {e}", p.display()))?;
    }
    write_atomic(&target, &bytes).map_err(|e| e.to_string())?;
    let version = format!("{}.{ext}", s.scan.id);
    Ok(Arrival {
        id: s.object.clone(),
        label: format!("{} (object {})", s.scan.label, s.object),
        input: Input::Object(folder),
        key: VersionKey {
            time: SystemTime::now(),
            tie: version.clone(),
        },
        version,
        detected: Instant::now(),
    })
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

    #[test]
    fn a_stored_scan_replaces_its_other_versions_and_its_transform() {
        let tmp = tempfile::tempdir().expect("tmp");
        let turn = [
            0., -1., 0., 0., 1., 0., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
        ];
        let first = ObjectScan {
            object: "o".into(),
            scan: inline("s", "obj", b"v 0 0 0\n"),
            transform: Some(turn),
        };
        let a = store_scan(tmp.path(), &first).expect("stored");
        let folder = tmp.path().join("o");
        assert!(matches!(&a.input, Input::Object(f) if *f == folder));
        assert_eq!(a.id, "o");
        let xf = std::fs::read_to_string(folder.join("s.xf")).expect("xf");
        let read = crate::io::registration::parse_xf(&xf, "s.xf").expect("rigid");
        assert_eq!(read.to_row_major(), turn);
        // A new version in another format without a transform: the old file and the .xf go.
        let second = ObjectScan {
            object: "o".into(),
            scan: inline("s", "ply", b"ply\n"),
            transform: None,
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
}
