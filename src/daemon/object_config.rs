//! The `[object]` table: subfolders of the watch folder as objects scanned view by view
//! (`pipeline::object_session`), and how their scans are merged.

use crate::pipeline::merge::MergeOptions;

/// The `[object]` table.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSection {
    /// Each subfolder of the watch folder is one object: every mesh in it is a registered
    /// scan of it, and the object gets one surface (`OUT/<folder>/`). Needs a restart.
    #[serde(default)]
    pub folders: bool,
    /// Each scan's distance to the object's surface in report.json (a point-to-mesh query
    /// per scan point).
    #[serde(default = "yes")]
    pub measure_scans: bool,
    /// Objects whose session (scans' samples, merge grid, last fit) stays in memory
    /// between updates, the ones updated last: their next update merges around the scans
    /// that changed and refits the previous control mesh locally where the ground is the
    /// same. 0: every update starts over from the folder. Needs a restart.
    #[serde(default = "kept_sessions")]
    pub kept_sessions: usize,
    /// `[object.merge]`: the merge of the scans.
    #[serde(default)]
    pub merge: MergeOptions,
}

fn kept_sessions() -> usize {
    4
}

fn yes() -> bool {
    true
}

impl Default for ObjectSection {
    fn default() -> Self {
        Self {
            folders: false,
            measure_scans: true,
            kept_sessions: kept_sessions(),
            merge: MergeOptions::default(),
        }
    }
}

/// The key, the value and the rule of the first bad `[object]` value.
pub(crate) fn validate_object(
    o: &ObjectSection,
) -> Result<(), (&'static str, String, &'static str)> {
    let m = &o.merge;
    let rules: [(bool, &'static str, f64, &'static str); 10] = [
        (
            m.cell.is_finite() && (0.0..=1.0).contains(&m.cell),
            "object.merge.cell",
            m.cell,
            "metres, 0..=1 (0: from the scans' spacing)",
        ),
        (
            (0.25..=16.0).contains(&m.cell_edges),
            "object.merge.cell_edges",
            m.cell_edges,
            "must be 0.25..=16",
        ),
        (
            (1.8..=8.0).contains(&m.radius_cells),
            "object.merge.radius_cells",
            m.radius_cells,
            "must be 1.8..=8 (a cell's corners must reach a sample)",
        ),
        (
            (0.1..=8.0).contains(&m.sigma_cells),
            "object.merge.sigma_cells",
            m.sigma_cells,
            "must be 0.1..=8",
        ),
        (
            m.rim_weight > 0.0 && m.rim_weight <= 1.0,
            "object.merge.rim_weight",
            m.rim_weight,
            "must be in (0, 1]",
        ),
        (
            m.fill_spacing_edges == 0.0 || (1.0..=16.0).contains(&m.fill_spacing_edges),
            "object.merge.fill_spacing_edges",
            m.fill_spacing_edges,
            "must be 0 (vertices only) or 1..=16 (never denser than the scan)",
        ),
        (
            (0.1..=8.0).contains(&m.keep_cells),
            "object.merge.keep_cells",
            m.keep_cells,
            "must be 0.1..=8",
        ),
        (
            (0.0..=4.0).contains(&m.rim_overhang_cells),
            "object.merge.rim_overhang_cells",
            m.rim_overhang_cells,
            "must be 0..=4",
        ),
        (
            m.ramp_rings <= 64 && m.projections <= 8,
            "object.merge.ramp_rings / projections",
            m.ramp_rings as f64,
            "ramp_rings <= 64 and projections <= 8",
        ),
        (
            o.kept_sessions <= 64,
            "object.kept_sessions",
            o.kept_sessions as f64,
            "must be 0..=64 (each holds an object's scans and merge grid in memory)",
        ),
    ];
    for (ok, key, value, rule) in rules {
        if !ok {
            return Err((key, value.to_string(), rule));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_pass_and_bad_merge_values_are_named() {
        assert!(validate_object(&ObjectSection::default()).is_ok());
        let mut o = ObjectSection::default();
        o.merge.radius_cells = 1.0;
        assert_eq!(
            validate_object(&o).err().map(|e| e.0),
            Some("object.merge.radius_cells")
        );
        let mut o = ObjectSection::default();
        o.merge.cell = f64::NAN;
        assert_eq!(
            validate_object(&o).err().map(|e| e.0),
            Some("object.merge.cell")
        );
        for bad in [0.1, f64::NAN, -2.0] {
            let mut o = ObjectSection::default();
            o.merge.fill_spacing_edges = bad;
            assert_eq!(
                validate_object(&o).err().map(|e| e.0),
                Some("object.merge.fill_spacing_edges")
            );
        }
        let mut o = ObjectSection::default();
        o.merge.rim_overhang_cells = -1.0;
        assert_eq!(
            validate_object(&o).err().map(|e| e.0),
            Some("object.merge.rim_overhang_cells")
        );
    }
}
