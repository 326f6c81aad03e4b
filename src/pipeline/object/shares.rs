//! The per-point weights of a squared-distance round: the tangential (point-to-point)
//! share and, with a curvature floor, the curvature's term.

use super::model::ObjectOptions;
use super::solve::Feet;

/// A round's tangential shares (`shares`) and, with `opts.curvature_floor`, the points'
/// curvature terms: away from the data's edges the share is then the floor, and the
/// curvature term, like the shares, scaled by the Levenberg-Marquardt factor `share /
/// opts.tangential`. Near the edges and on the rim the shares are the constant ones:
/// there the data end, and the foot points of a rim are held on the boundary curve.
pub(super) fn shares_and_curvature(
    (near_edge, on_rim): (&[bool], &[bool]),
    feet: &Feet,
    (share, edge_factor): (f64, f64),
    opts: &ObjectOptions,
) -> (Vec<f64>, Option<Vec<[f64; 6]>>) {
    let mut tangential = shares(near_edge, on_rim, share, edge_factor);
    let Some(floor) = opts.curvature_floor else {
        return (tangential, None);
    };
    let damping = share / opts.tangential.max(f64::MIN_POSITIVE);
    let mut curvature = vec![[0.0; 6]; tangential.len()];
    for (i, t) in tangential.iter_mut().enumerate() {
        if near_edge[i] || on_rim[i] {
            continue;
        }
        *t = floor * damping;
        if let Some(c) = feet.curvature.get(i) {
            curvature[i] = c.map(|x| x * damping);
        }
    }
    (tangential, Some(curvature))
}

/// Per data point, the share of the point-to-point term in a round: `share` inside,
/// `edge_factor` times more near the data's boundary, and all of it on the rim, where the
/// boundary curve has to reach the points.
fn shares(near_edge: &[bool], on_rim: &[bool], share: f64, edge_factor: f64) -> Vec<f64> {
    near_edge
        .iter()
        .zip(on_rim)
        .map(|(&e, &r)| match (r, e) {
            (true, _) => 1.0,
            (false, true) => share * edge_factor,
            (false, false) => share,
        })
        .collect()
}
