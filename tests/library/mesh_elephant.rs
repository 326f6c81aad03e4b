//! The semi-regular elephant: subd2 is an exact two-level 1-to-4 split of subd0.

use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::inverse::{coarsen, InverseMethod};
use trispline::mesh::loop_subdiv::subdivide;
use trispline::testdata::shared_data;

fn canonical(t: [u32; 3]) -> [u32; 3] {
    let k = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

#[test]
fn subd2_coarsens_to_exactly_subd0_connectivity() {
    let (Some(p0), Some(p2)) = (
        shared_data("semi_regular/subd0.obj"),
        shared_data("semi_regular/subd2.obj"),
    ) else {
        return;
    };
    let m0 = read_mesh_file(&p0, &LoadOptions::default())
        .expect("subd0")
        .mesh;
    let m2 = read_mesh_file(&p2, &LoadOptions::default())
        .expect("subd2")
        .mesh;
    let stats = trispline::mesh::stats::mesh_stats(&m2, 4);
    assert_eq!(stats.subdivision_depth, 2, "{:?}", stats.subdivision_note);
    for method in [InverseMethod::Exact, InverseMethod::Lsq] {
        let c = coarsen(&m2, 2, method).expect("depth 2");
        assert_eq!(c.mesh.positions.len(), m0.positions.len());
        let mut want: Vec<_> = m0.triangles.iter().map(|t| canonical(*t)).collect();
        let mut got: Vec<_> = c.mesh.triangles.iter().map(|t| canonical(*t)).collect();
        want.sort_unstable();
        got.sort_unstable();
        assert_eq!(want, got, "{method:?}: coarse faces differ from subd0");
        // subd2's odd vertices lie on the original surface, not at Loop positions, so the
        // inverse does not return subd0's positions; measure how far it lands.
        let diag = m0.bounds_diagonal();
        let dist: Vec<f64> = c
            .mesh
            .positions
            .iter()
            .zip(&m0.positions)
            .map(|(a, b)| (*a - *b).length())
            .collect();
        let max = dist.iter().cloned().fold(0.0, f64::max);
        let rms = (dist.iter().map(|d| d * d).sum::<f64>() / dist.len() as f64).sqrt();
        eprintln!("elephant {method:?}: coarse vs subd0 positions max {:.4} rms {:.4} (bbox diagonal {diag:.3})", max, rms);
        assert!(
            max < 0.5 * diag,
            "{method:?}: inverse positions far off ({max} vs diagonal {diag})"
        );
        // Re-subdividing the recovered net gives subd2's connectivity back exactly.
        let again = subdivide(&c.mesh, 2).expect("manifold");
        assert_eq!(again.triangles.len(), m2.triangles.len());
    }
}
