//! Locating the third-party test data in `../shared/data` (never committed here).

use std::path::PathBuf;

/// Path of a file under `../shared/data`, or `None` when the folder is absent so that a
/// test can skip. With `TRISPLINE_REQUIRE_DATA=1` (set by `.ci/run`) a missing file panics
/// instead: CI must never pass by skipping.
pub fn shared_data(relative: &str) -> Option<PathBuf> {
    let root = std::env::var_os("TRISPLINE_DATA_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let path = root.join(relative);
    if path.exists() {
        return Some(path);
    }
    if std::env::var("TRISPLINE_REQUIRE_DATA").is_ok_and(|v| v == "1") {
        panic!("TRISPLINE_REQUIRE_DATA=1 but {} is missing", path.display());
    }
    eprintln!("skipping: {} not found", path.display());
    None
}
