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

/// Every Stanford range scan in the shared data, relative to its root: the raw and the
/// registered views, the range grid and MeshLab's triangulation (the scans the coverage
/// goal is measured on).
pub const STANFORD_SCANS: [&str; 10] = [
    "range_scans/bun000_tri.ply",
    "range_scans/bun045_tri.ply",
    "range_scans/chin_tri.ply",
    "range_scans/bun000_range_grid.ply",
    "range_scans/bun000_meshlab_triangulated.ply",
    "range_scans/registered/bun000.ply",
    "range_scans/registered/bun045.ply",
    "range_scans/registered/bun180.ply",
    "range_scans/registered/bun270.ply",
    "range_scans/registered/chin.ply",
];
