//! DMS splines in piece form at every degree: each knot-line cell's polynomials, expanded
//! about the cell's own centre, against Micchelli's recurrence at the point and against the
//! partition of unity.

use super::bpatch_dms::{random_dms, test_params, Rng};
use glam::DVec2;
use trispline::surface::dms::PlanarSurface;
use trispline::surface::TriSurface;

/// Partition of unity of the basis rows (the piece path) to 1e-12, at random points and at
/// every face's corners and edge points, degrees 1 to 3 on random knot clouds. In monomials
/// about each family's centre degree 3 was 4e-9 off (why degree 3 walked the recurrence).
#[test]
fn dms_pieces_are_a_partition_of_unity_to_1e_12_at_every_degree() {
    for degree in 1..=3 {
        for seed in [4, 5, 6] {
            let s = random_dms(degree, seed * 17 + degree as u64);
            let mut rng = Rng(seed + 200);
            let mut row = Vec::new();
            let mut worst = 0.0f64;
            for p in test_params(s.domain_face_count(), &mut rng, 400) {
                s.basis_row(p, &mut row);
                let sum: f64 = row.iter().map(|r| r.1).sum();
                worst = worst.max((sum - 1.0).abs());
            }
            assert!(
                s.piece_count() > 0,
                "degree {degree}: the rows came from pieces"
            );
            assert!(
                worst < 1e-12,
                "degree {degree} seed {seed}: |sum - 1| up to {worst:e}"
            );
        }
    }
}

/// Every triangle's basis from its kept pieces equals the recurrence at the point: values
/// to 1e-12, first and second derivatives to 1e-9 of their magnitude, on and off knot lines
/// (face corners and edges lie on knot lines of the clouds' vertices).
#[test]
fn dms_pieces_agree_with_the_recurrence_at_degrees_2_and_3() {
    for degree in [2, 3] {
        let s = random_dms(degree, 300 + degree as u64);
        let mut rng = Rng(41 + degree as u64);
        let params = test_params(s.domain_face_count(), &mut rng, 500);
        let (mut scratch, mut walked, mut kept) = (Vec::new(), Vec::new(), Vec::new());
        let mut worst = [0.0f64; 3];
        for p in params {
            let x = s.domain_point(p);
            let [a, b, c] = s.triangles()[p.face as usize].map(|v| s.vertices()[v as usize]);
            let dir: DVec2 = (a + b + c) / 3.0 - x;
            for t in 0..s.domain_face_count() {
                let family = s.family(t).expect("a family per triangle");
                family.evaluate::<true>(x, dir, &mut scratch, &mut walked);
                family.evaluate_cached::<true>(x, dir, &mut scratch, &mut kept);
                for (w, k) in walked.iter().zip(&kept) {
                    let first = w[1].abs().max(w[2].abs());
                    let second = w[3].abs().max(w[4].abs()).max(w[5].abs());
                    worst[0] = worst[0].max((w[0] - k[0]).abs());
                    worst[1] =
                        worst[1].max((w[1] - k[1]).abs().max((w[2] - k[2]).abs()) / (1.0 + first));
                    worst[2] = worst[2].max(
                        (3..6).map(|i| (w[i] - k[i]).abs()).fold(0.0, f64::max) / (1.0 + second),
                    );
                }
            }
        }
        assert!(
            worst[0] < 1e-12 && worst[1] < 1e-9 && worst[2] < 1e-9,
            "degree {degree}: value, first and second derivative differences {worst:?}"
        );
    }
}
