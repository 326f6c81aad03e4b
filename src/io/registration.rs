//! Where a registered scan sits in its object's frame, as scanning software writes it:
//! Stanford's sidecar `<scan>.xf` (a 4x4 matrix, row by row) and Stanford's `.conf` (one
//! `bmesh <file> tx ty tz qx qy qz qw` line per scan). Only the numbers are read here;
//! the transform is `mesh::rigid`'s.
//!
//! The `.conf` convention was measured on the shared bunny scans (`bun.conf`, 46-75 um
//! median distance to Stanford's own reconstruction; the other three readings of the same
//! numbers put the views centimetres apart): a scan's point p goes to `R^T p + t`, with R
//! the rotation matrix of the unit quaternion (qx, qy, qz, qw) and t = (tx, ty, tz).

use super::{read_limited, IoError, IoErrorKind};
use crate::mesh::rigid::{RigidError, RigidTransform};
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Registration files are a few lines; anything bigger is not one.
const MAX_REGISTRATION_BYTES: u64 = 1 << 20;

/// Where a scan's transform was found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "from")]
pub enum RegistrationSource {
    /// A sidecar `.xf` beside the scan.
    Sidecar {
        /// The `.xf` file.
        file: PathBuf,
    },
    /// A line of a `.conf` in the scan's folder.
    Conf {
        /// The `.conf` file.
        file: PathBuf,
        /// Its line (1-based).
        line: usize,
    },
    /// Given with the scan (a pipe record's `transform`).
    Given,
    /// Nothing registers the scan: it is in the object's frame already.
    Identity,
}

/// A scan's transform into its object's frame and where it came from.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Registration {
    /// The rigid motion.
    pub transform: RigidTransform,
    /// Its origin.
    pub source: RegistrationSource,
}

fn not_rigid(file: &str, location: Option<String>, e: RigidError) -> IoError {
    IoError::new(file, location, IoErrorKind::NotRigid(e))
}

/// The numbers of a whitespace-separated list, or which word is no number.
fn numbers(words: &[&str]) -> Result<Vec<f64>, String> {
    words
        .iter()
        .enumerate()
        .map(|(i, w)| {
            w.parse::<f64>()
                .map_err(|_| format!("word {} ('{w}') is not a number", i + 1))
        })
        .collect()
}

/// Reads a Stanford `.xf`: 16 numbers, the 4x4 matrix row by row (p' = M p).
pub fn parse_xf(text: &str, name: &str) -> Result<RigidTransform, IoError> {
    let words: Vec<&str> = text.split_whitespace().collect();
    if words.is_empty() {
        return Err(IoError::new(name, None, IoErrorKind::Empty));
    }
    let values =
        numbers(&words).map_err(|d| IoError::new(name, None, IoErrorKind::malformed(d)))?;
    RigidTransform::from_row_major(&values).map_err(|e| not_rigid(name, None, e))
}

/// The transform a `.conf` gives the scan whose file stem is `scan_id`, with the line it
/// is on; `None` when no `bmesh` (or `mesh`) line names such a file. A line that names it
/// with missing or bad numbers is an error, never the identity.
pub fn conf_transform(
    text: &str,
    name: &str,
    scan_id: &str,
) -> Option<Result<(RigidTransform, usize), IoError>> {
    for (k, line) in text.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let [keyword, file, rest @ ..] = words.as_slice() else {
            continue;
        };
        if !matches!(*keyword, "bmesh" | "mesh") {
            continue;
        }
        if Path::new(file).file_stem().and_then(|s| s.to_str()) != Some(scan_id) {
            continue;
        }
        let location = Some(format!("line {}", k + 1));
        let parsed = numbers(rest)
            .map_err(|d| IoError::new(name, location.clone(), IoErrorKind::malformed(d)))
            .and_then(|v| {
                if v.len() != 7 {
                    return Err(not_rigid(
                        name,
                        location.clone(),
                        RigidError::Count {
                            expected: 7,
                            found: v.len(),
                        },
                    ));
                }
                RigidTransform::from_quaternion(
                    DVec3::new(v[0], v[1], v[2]),
                    [v[3], v[4], v[5], v[6]],
                )
                .map(RigidTransform::with_rotation_transposed)
                .map_err(|e| not_rigid(name, location.clone(), e))
            });
        return Some(parsed.map(|t| (t, k + 1)));
    }
    None
}

fn read_text(path: &Path) -> Result<String, IoError> {
    let name = path.display().to_string();
    let bytes = read_limited(path, MAX_REGISTRATION_BYTES, "the registration file")
        .map_err(|kind| IoError::new(&name, None, kind))?;
    String::from_utf8(bytes)
        .map_err(|_| IoError::new(&name, None, IoErrorKind::NotText { what: "the file" }))
}

/// The registration of the scan file `scan` whose id is `scan_id`, in this order: a
/// sidecar `<file stem>.xf` or `<scan_id>.xf` beside it, the first `.conf` of its folder
/// (in name order) that names the scan, else the identity. A sidecar or a `.conf` line
/// that names the scan and cannot be read is an error.
pub fn registration_for(scan: &Path, scan_id: &str) -> Result<Registration, IoError> {
    let folder = scan.parent().unwrap_or(Path::new("."));
    let stem = scan.file_stem().and_then(|s| s.to_str()).unwrap_or(scan_id);
    for candidate in [stem, scan_id] {
        let xf = folder.join(format!("{candidate}.xf"));
        if xf.is_file() {
            let text = read_text(&xf)?;
            let transform = parse_xf(&text, &xf.display().to_string())?;
            return Ok(Registration {
                transform,
                source: RegistrationSource::Sidecar { file: xf },
            });
        }
    }
    let mut confs: Vec<PathBuf> = std::fs::read_dir(folder)
        .map_err(|e| IoError::new(folder.display().to_string(), None, IoErrorKind::Open(e)))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("conf"))
                && p.is_file()
        })
        .collect();
    confs.sort();
    for conf in confs {
        let text = read_text(&conf)?;
        if let Some(found) = conf_transform(&text, &conf.display().to_string(), scan_id) {
            let (transform, line) = found?;
            return Ok(Registration {
                transform,
                source: RegistrationSource::Conf { file: conf, line },
            });
        }
    }
    Ok(Registration {
        transform: RigidTransform::IDENTITY,
        source: RegistrationSource::Identity,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const CONF: &str = "camera -0.0172 -0.0936 -0.734  -0.0461723 0.970603 -0.235889 0.0124573\n\
        bmesh bun000.ply 0 0 0 0 0 0 1\n\
        bmesh bun045.ply -0.0520211 -0.000383981 -0.0109223 0.00548449 -0.294635 -0.0038555 0.955586\n\
        bmesh bad.ply 0 0 0 0 0 x 1\n\
        bmesh short.ply 0 0 0 0 0 1\n\
        bmesh scaled.ply 0 0 0 0 0 0 3\n";

    #[test]
    fn a_conf_line_gives_r_transposed_and_the_translation() {
        let (t, line) = conf_transform(CONF, "bun.conf", "bun045")
            .expect("named")
            .expect("valid");
        assert_eq!(line, 3);
        let q = glam::DQuat::from_xyzw(0.00548449, -0.294635, -0.0038555, 0.955586).normalize();
        let p = DVec3::new(0.01, 0.02, 0.03);
        let expected = q.inverse() * p + DVec3::new(-0.0520211, -0.000383981, -0.0109223);
        assert!((t.apply(p) - expected).length() < 1e-12);
        let (identity, _) = conf_transform(CONF, "bun.conf", "bun000")
            .expect("named")
            .expect("valid");
        assert!((identity.apply(p) - p).length() < 1e-15);
        assert!(conf_transform(CONF, "bun.conf", "camera").is_none());
        assert!(conf_transform(CONF, "bun.conf", "bun090").is_none());
    }

    #[test]
    fn a_conf_line_with_bad_numbers_is_an_error_naming_the_line_never_the_identity() {
        let kind = |id: &str| {
            conf_transform(CONF, "bun.conf", id)
                .expect("named")
                .map_err(|e| (e.kind(), e.to_string()))
                .err()
        };
        let (k, message) = kind("bad").expect("refused");
        assert_eq!(k, "malformed");
        assert!(message.contains("line 4"), "{message}");
        assert_eq!(kind("short").map(|e| e.0), Some("not_rigid"));
        assert_eq!(kind("scaled").map(|e| e.0), Some("not_rigid"));
    }

    #[test]
    fn an_xf_is_sixteen_numbers_of_a_rigid_motion() {
        let xf = "1 0 0 0.5\n0 0 -1 0\n0 1 0 0\n0 0 0 1\n";
        let t = parse_xf(xf, "s.xf").expect("rigid");
        assert!((t.apply(DVec3::new(0.0, 1.0, 0.0)) - DVec3::new(0.5, 0.0, 1.0)).length() < 1e-15);
        assert_eq!(
            parse_xf("", "s.xf").map_err(|e| e.kind()).err(),
            Some("empty")
        );
        assert_eq!(
            parse_xf("1 0 0 0 0 1 0 0 0 0 1 0", "s.xf")
                .map_err(|e| e.kind())
                .err(),
            Some("not_rigid")
        );
        assert_eq!(
            parse_xf("2 0 0 0 0 2 0 0 0 0 2 0 0 0 0 1", "s.xf")
                .map_err(|e| e.kind())
                .err(),
            Some("not_rigid")
        );
        assert_eq!(
            parse_xf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 one", "s.xf")
                .map_err(|e| e.kind())
                .err(),
            Some("malformed")
        );
    }

    #[test]
    fn the_sidecar_comes_before_the_conf_and_nothing_means_identity() {
        let dir = tempfile::tempdir().expect("temp dir");
        std::fs::write(dir.path().join("bun.conf"), CONF).expect("write");
        let scan = dir.path().join("bun045.ply");
        let from_conf = registration_for(&scan, "bun045").expect("conf");
        assert!(matches!(
            from_conf.source,
            RegistrationSource::Conf { line: 3, .. }
        ));
        std::fs::write(
            dir.path().join("bun045.xf"),
            "1 0 0 1 0 1 0 2 0 0 1 3 0 0 0 1",
        )
        .expect("write");
        let sidecar = registration_for(&scan, "bun045").expect("xf");
        assert!(matches!(sidecar.source, RegistrationSource::Sidecar { .. }));
        assert_eq!(sidecar.transform.translation, DVec3::new(1.0, 2.0, 3.0));
        let other = registration_for(&dir.path().join("rabbit.ply"), "rabbit").expect("none");
        assert_eq!(other.source, RegistrationSource::Identity);
        let bad = registration_for(&dir.path().join("bad.ply"), "bad");
        assert_eq!(bad.map_err(|e| e.kind()).err(), Some("malformed"));
    }
}
