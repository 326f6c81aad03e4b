//! Patch ids: how an input's name (a file stem, a relative path, a pipe record's id)
//! becomes an id that is safe as a folder name in OUT, and which names are inputs at all.
//! Apart from `messages` so that what reads files by name (the watcher, object folders)
//! need not import the threads' messages.

use super::state;
use crate::io::Format;
use std::path::Path;

/// Output names a patch folder must never take: OUT holds them beside the patch folders.
const RESERVED_IDS: [&str; 3] = ["quarantine", "processed", "events.ndjson"];

/// A patch id from a pipe record or a file stem, safe as a folder name in OUT: letters and
/// digits of any script, `_`, `-` and `.` are kept; anything else (and a leading or trailing
/// dot, a reserved name, an id that looks like a component's, an overlong id) is replaced
/// and marked with `~` and a hash of the raw id. `~` never survives sanitising, so a marked
/// id cannot equal a clean one and two raw ids differ after sanitising unless their hashes
/// collide. No sanitised id ends in `.c<digits>`, so component outputs (`<id>.c<k>`) live in
/// a namespace of their own. `None` for an empty id.
pub(crate) fn sanitize_id(raw: &str) -> Option<String> {
    const MAX_CHARS: usize = 120;
    if raw.is_empty() {
        return None;
    }
    let mut changed = false;
    let mut id: String = raw
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || c == '_' || c == '-' || c == '.' {
                c
            } else {
                changed = true;
                '_'
            }
        })
        .collect();
    let trimmed = id.trim_matches('.');
    if trimmed.len() != id.len() {
        changed = true;
        id = trimmed.to_string();
    }
    if id.chars().count() > MAX_CHARS {
        changed = true;
        id = id.chars().take(MAX_CHARS).collect();
    }
    let reserved = RESERVED_IDS
        .iter()
        .any(|r| id == *r || id.starts_with(&format!("{r}.")));
    if changed || reserved || looks_like_component(&id) {
        let hash = state::content_hash(raw.as_bytes());
        id = format!("{id}~{:08x}", hash as u32 ^ (hash >> 32) as u32);
    }
    Some(id)
}

/// `<anything>.c<digits>`: the shape of a component's id (`pipeline::worker::run_input`
/// suffixes `.c<k>`), which a patch of its own must not take, or patch `x.c0` and
/// component 0 of patch `x` would share a folder and a state.
fn looks_like_component(id: &str) -> bool {
    id.rsplit_once(".c")
        .is_some_and(|(_, k)| !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()))
}

/// The id of component `suffix` (`.c<k>`, or empty for the whole input) of patch `id`.
/// Disjoint from every `sanitize_id` result (none ends in `.c<digits>`), and from every
/// other component's id: `k` is all digits, so the last `.c` of the result splits it back
/// into `id` and `k`.
pub(crate) fn part_id(id: &str, suffix: &str) -> String {
    format!("{id}{suffix}")
}

/// Patch id of a file: the stem up to the first '@', sanitised.
pub(crate) fn patch_id(path: &Path) -> Option<String> {
    let stem = path.file_stem()?.to_str()?;
    sanitize_id(stem.split('@').next().unwrap_or(stem))
}

/// Patch id of a file under the watch folder `root`: its folder names (each sanitised like
/// an id) and its own patch id, joined by `/` (`scans/ear@3.ply` -> `scans/ear`), so that
/// its outputs go to `OUT/scans/ear/`. A file directly in `root` gets `patch_id`. The one
/// place that turns a relative path into an id, for whatever groups files by folder.
/// `None` when the path is not under `root` or a part leaves no id.
pub(crate) fn relative_patch_id(root: &Path, path: &Path) -> Option<String> {
    let rel = path.strip_prefix(root).ok()?;
    let mut parts = Vec::new();
    if let Some(folders) = rel.parent() {
        for c in folders.components() {
            let std::path::Component::Normal(name) = c else {
                return None;
            };
            parts.push(sanitize_id(name.to_str()?)?);
        }
    }
    parts.push(patch_id(rel)?);
    Some(parts.join("/"))
}

/// Names that are still being written or are not meshes.
pub(crate) fn ignored(path: &Path) -> bool {
    partial_name(path) || Format::from_path(path).is_none()
}

/// Names that writers give a file before its rename to the real name (hidden, `.tmp`,
/// `.part`), or no usable name at all.
pub(crate) fn partial_name(path: &Path) -> bool {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return true;
    };
    name.starts_with('.') || name.ends_with(".tmp") || name.ends_with(".part")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_before_their_rename_are_partial_and_meshes_otherwise_taken() {
        for name in [".bun045.xf", "bun045.xf.tmp", "scan.ply.part", ".scan.ply"] {
            assert!(partial_name(Path::new(name)), "{name}");
            assert!(ignored(Path::new(name)), "{name}");
        }
        assert!(!partial_name(Path::new("bun045.xf")));
        assert!(ignored(Path::new("bun045.xf")), "no mesh");
        assert!(!ignored(Path::new("in/bun045.ply")));
    }

    #[test]
    fn patch_ids_are_safe_and_distinct() {
        let ids: Vec<String> = [
            "测试",
            "例子",
            "ear",
            "ear_",
            "ear?",
            "ear*",
            "a/b",
            "a_b",
            "..",
            ".hidden",
            "quarantine",
            "processed",
            "events.ndjson",
            "events.ndjson.torn",
            "x~1",
        ]
        .iter()
        .map(|raw| sanitize_id(raw).expect("an id"))
        .collect();
        assert_eq!(ids[0], "测试");
        assert_eq!(ids[2], "ear");
        let unique: std::collections::HashSet<&String> = ids.iter().collect();
        assert_eq!(unique.len(), ids.len(), "{ids:?}");
        for id in &ids {
            assert!(
                !id.contains('/') && !id.starts_with('.') && !id.is_empty(),
                "{id}"
            );
            assert!(!RESERVED_IDS.contains(&id.as_str()), "{id}");
        }
        assert!(ids[3] == "ear_" && ids[4].starts_with("ear_~"), "{ids:?}");
        assert_eq!(sanitize_id(""), None);
        let long = "x".repeat(500);
        assert!(sanitize_id(&long).expect("id").len() < 140);
        assert_eq!(
            patch_id(Path::new("/in/测试@0003.obj")).as_deref(),
            Some("测试")
        );
    }

    /// Patch `x.c0` used to be written to the folder (and state) of component 0 of `x`.
    #[test]
    fn patch_ids_never_take_a_components_id() {
        let raws = [
            "x", "x.c0", "x.c1", "x.c12", "x.c0.c1", "y.c", "y.cz", "y.c0a",
        ];
        let ids: Vec<String> = raws
            .iter()
            .map(|r| sanitize_id(r).expect("an id"))
            .collect();
        assert_eq!(ids[0], "x");
        for (raw, id) in raws[1..5].iter().zip(&ids[1..5]) {
            assert!(looks_like_component(raw), "{raw}");
            assert!(id.starts_with(raw) && id.contains('~'), "{raw} -> {id}");
        }
        // Only `.c` followed by digits is a component's shape.
        assert_eq!(&ids[5..], &["y.c", "y.cz", "y.c0a"]);
        let mut all: Vec<String> = ids.clone();
        for id in &ids {
            for k in 0..12 {
                all.push(part_id(id, &format!(".c{k}")));
            }
        }
        let unique: std::collections::HashSet<&String> = all.iter().collect();
        assert_eq!(unique.len(), all.len(), "{all:?}");
        assert!(
            all.contains(&"x.c0".to_string()),
            "component 0 of x keeps its name"
        );
    }

    #[test]
    fn relative_ids_keep_folders_apart_and_safe() {
        let root = Path::new("/in");
        let id = |p: &str| relative_patch_id(root, Path::new(p));
        assert_eq!(id("/in/ear@2.ply").as_deref(), Some("ear"));
        assert_eq!(id("/in/scans/ear@2.ply").as_deref(), Some("scans/ear"));
        assert_eq!(id("/in/a/b/c.obj").as_deref(), Some("a/b/c"));
        assert_eq!(id("/elsewhere/x.ply"), None);
        // Folder names are sanitised like ids: no `..`, no reserved name, distinct.
        let odd = id("/in/quarantine/x.ply").expect("id");
        assert!(
            odd.starts_with("quarantine~") && odd.ends_with("/x"),
            "{odd}"
        );
        let (a, b) = (id("/in/a b/x.ply"), id("/in/a_b/x.ply"));
        assert_ne!(a, b);
        assert!(id("/in/.hidden/x.ply").is_some_and(|i| !i.starts_with('.')));
    }
}
