//! What a user is shown of a Stanford scan, measured from the worker's bytes alone: the GLB
//! read back covers the fitted points (>= 99.5 % within 1 mm, rims included) and shows
//! nothing farther from the data than the bridging distance; the colours' ramp and scale
//! travel with it.

use trispline::io::{read_mesh_bytes, read_mesh_file, Format, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::scan::components::cleaned_components;
use trispline::pipeline::worker::{run_input, WorkerConfig};
use trispline::testdata::shared_data;
use trispline::{DVec3, TriMesh};

/// Share of `points` within `near` of `shown`.
pub(crate) fn share_within(shown: &TriMesh, points: &[DVec3], near: f64) -> f64 {
    let md = MeshDistance::new(shown);
    let within = points
        .iter()
        .filter(|p| md.distance(**p).is_some_and(|d| d <= near))
        .count();
    within as f64 / points.len().max(1) as f64
}

/// The JSON chunk of a GLB.
fn glb_json(bytes: &[u8]) -> serde_json::Value {
    let len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
    serde_json::from_slice(&bytes[20..20 + len]).expect("glb json chunk")
}

#[test]
fn every_stanford_scan_is_shown_where_it_was_fitted() {
    let scans = trispline::testdata::STANFORD_SCANS;
    let cfg = WorkerConfig::default();
    let mut failures = Vec::new();
    for rel in scans {
        let Some(path) = shared_data(rel) else {
            return;
        };
        let mesh = read_mesh_file(&path, &LoadOptions::default())
            .expect("reads")
            .mesh;
        let outputs = run_input(&mesh, None, &cfg).expect("fits");
        assert_eq!(outputs.parts.len(), 1, "{rel}: one surface by default");
        let out = &outputs.parts[0].outputs;
        // The fitted points, found here and not from the report: the largest piece of the
        // cleaned input (the report's count only confirms it).
        let fitted = cleaned_components(&clean(&mesh, &CleanOptions::default()))
            .into_iter()
            .next()
            .expect("a piece");
        assert_eq!(
            out.report["data_points"].as_u64(),
            Some(fitted.positions.len() as u64),
            "{rel}"
        );
        let shown = read_mesh_bytes(&out.glb, Format::Glb, rel, &LoadOptions::default())
            .expect("the GLB reads back")
            .mesh;
        let share = share_within(&shown, &fitted.positions, 1e-3);
        // Nothing shown far from the data: the farthest shown vertex from the input.
        let data = MeshDistance::new(&mesh);
        let farthest = shown
            .positions
            .iter()
            .filter_map(|p| data.distance(*p))
            .fold(0.0f64, f64::max);
        eprintln!(
            "{rel}: {:.3} % of {} fitted points within 1 mm of the GLB; farthest shown vertex {:.0} um",
            100.0 * share,
            fitted.positions.len(),
            farthest * 1e6
        );
        // Issue 21: 99.5 % within 1 mm, and no flaps: every shown vertex within the
        // bridging distance of the data (the report's `holes.max_bridge`, 1.14-1.21 mm
        // here) and under 1.5 mm. Measured: 99.990-100 %, farthest 1142-1208 um.
        let bridge = out.report["holes"]["max_bridge"]
            .as_f64()
            .expect("max_bridge");
        if share < 0.995 || farthest > bridge + 1e-9 || farthest >= 1.5e-3 {
            failures.push(format!(
                "{rel}: {:.3} % within 1 mm (needs 99.5 %), farthest shown {:.0} um (needs <= {:.0} and < 1500)",
                100.0 * share,
                farthest * 1e6,
                bridge * 1e6
            ));
        }
        // The colours' meaning travels with them: the same ramp in the GLB and the report.
        let ramp = &glb_json(&out.glb)["meshes"][0]["extras"]["error_ramp"];
        assert_eq!(ramp, &out.report["error_ramp"], "{rel}");
        assert_eq!(ramp["tolerance"], out.report["tolerance"], "{rel}");
        assert!(out.legend.starts_with("<svg"), "{rel}: legend");
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
