//! Where a control face is cut into patches: the lattice nodes that faces meeting there
//! agree on, and the sub-triangles of each face.
//!
//! Two kinds of split, both conforming (no patch corner ever lies inside another patch's
//! edge, so shared edges stay shared curves):
//! - uniform: every face cut into 4^depth triangles;
//! - at irregular vertices: each level halves, at their midpoints, the edges that end at an
//!   irregular vertex (extraordinary, boundary, crease, corner), where the limit surface is
//!   no polynomial and a quartic fits worst. Both faces of such an edge have that vertex
//!   as a corner, so both cut it: the split conforms. A triangle with one irregular corner
//!   becomes its corner triangle (split again at the next level) and two others; one with
//!   more is cut into four. This is the isolation of extraordinary vertices that adaptive
//!   subdivision (feature-adaptive refinement) does, for the same reason.

/// Lattice steps per face side: every split point is a multiple of 1 / STEPS.
pub(super) const STEPS: u32 = 1 << 20;

/// A point of the split lattice, named so that the faces meeting there agree on it.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub(super) enum Node {
    /// A control vertex.
    Corner(u32),
    /// On the control edge (low, high), this many lattice steps from `low`.
    OnEdge(u32, u32, u32),
    /// Inside a control face, at lattice (i, j).
    Inside(u32, u32, u32),
}

/// A lattice point (i, j) of a face: barycentric weights (i, j, STEPS - i - j) / STEPS of
/// its corners.
pub(super) type Lattice = (u32, u32);

/// Lattice point `(i, j)` of `face` (corners `corners`).
pub(super) fn node(face: usize, corners: [u32; 3], (i, j): Lattice) -> Node {
    let n = STEPS;
    let w = [i, j, n - i - j];
    if let Some(c) = (0..3).find(|&c| w[c] == n) {
        return Node::Corner(corners[c]);
    }
    if let Some(zero) = (0..3).find(|&c| w[c] == 0) {
        let (a, b) = ((zero + 1) % 3, (zero + 2) % 3);
        return if corners[a] < corners[b] {
            Node::OnEdge(corners[a], corners[b], w[b])
        } else {
            Node::OnEdge(corners[b], corners[a], w[a])
        };
    }
    Node::Inside(face as u32, i, j)
}

/// The face parameter (u, v) of a lattice point.
pub(super) fn param((i, j): Lattice) -> (f64, f64) {
    (i as f64 / STEPS as f64, j as f64 / STEPS as f64)
}

/// The sub-triangles of a face with these irregular corners: cut uniformly `depth` times,
/// then `levels` times at the irregular corners. In the face's own orientation.
pub(super) fn sub_triangles(depth: u32, levels: u32, irregular: [bool; 3]) -> Vec<[Lattice; 3]> {
    let n = 1u32 << depth;
    let scale = STEPS / n;
    let mut out = Vec::with_capacity((n * n) as usize);
    for i in 0..n {
        for j in 0..n - i {
            let s = |a: u32, b: u32| (a * scale, b * scale);
            out.push([s(i + 1, j), s(i, j + 1), s(i, j)]);
            if i + j + 2 <= n {
                out.push([s(i + 1, j + 1), s(i, j + 1), s(i + 1, j)]);
            }
        }
    }
    let face_corners = [(STEPS, 0), (0, STEPS), (0, 0)];
    let at_irregular = |p: Lattice| (0..3).any(|c| irregular[c] && face_corners[c] == p);
    for _ in 0..levels {
        out = out
            .into_iter()
            .flat_map(|t| {
                let marked: Vec<usize> = (0..3).filter(|&k| at_irregular(t[k])).collect();
                match marked[..] {
                    [] => vec![t],
                    [k] => cut_at_corner([t[k], t[(k + 1) % 3], t[(k + 2) % 3]]),
                    _ => cut_in_four(t),
                }
            })
            .collect();
    }
    out
}

fn midpoint(a: Lattice, b: Lattice) -> Lattice {
    ((a.0 + b.0) / 2, (a.1 + b.1) / 2)
}

/// The corner triangle at `t[0]` and the two that fill the rest (edges from `t[0]` halved).
fn cut_at_corner(t: [Lattice; 3]) -> Vec<[Lattice; 3]> {
    let (m01, m02) = (midpoint(t[0], t[1]), midpoint(t[0], t[2]));
    vec![[t[0], m01, m02], [m01, t[1], t[2]], [m01, t[2], m02]]
}

/// The four halves-of-every-edge triangles.
fn cut_in_four(t: [Lattice; 3]) -> Vec<[Lattice; 3]> {
    let (m01, m12, m20) = (
        midpoint(t[0], t[1]),
        midpoint(t[1], t[2]),
        midpoint(t[2], t[0]),
    );
    vec![
        [t[0], m01, m20],
        [m01, t[1], m12],
        [m20, m12, t[2]],
        [m01, m12, m20],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_nodes_agree_across_a_shared_edge() {
        // Faces (0, 1, 2) and (1, 0, 3) share edge 0-1 with opposite orientation.
        for k in [0, 1, STEPS / 4, STEPS / 2, STEPS - 1, STEPS] {
            let here = node(0, [0, 1, 2], (STEPS - k, k));
            let there = node(1, [1, 0, 3], (k, STEPS - k));
            assert_eq!(here, there);
        }
        assert_eq!(node(0, [0, 1, 2], (1, 1)), Node::Inside(0, 1, 1));
    }

    /// Twice the signed area of a lattice triangle.
    fn area2(t: &[Lattice; 3]) -> i64 {
        let p = t.map(|(i, j)| (i as i64, j as i64));
        (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1)
    }

    #[test]
    fn splits_tile_the_face_in_its_orientation() {
        let whole = area2(&[(STEPS, 0), (0, STEPS), (0, 0)]);
        for (depth, levels, irregular, count) in [
            (0, 0, [false; 3], 1),
            (2, 0, [false; 3], 16),
            (0, 3, [true, false, false], 7),
            (0, 2, [true, true, false], 4 + 2 * 2),
            (1, 2, [false, false, true], 4 + 2 * 2),
        ] {
            let t = sub_triangles(depth, levels, irregular);
            assert_eq!(t.len(), count, "{depth} {levels} {irregular:?}");
            assert!(t.iter().all(|t| area2(t) > 0), "orientation kept");
            assert_eq!(t.iter().map(area2).sum::<i64>(), whole, "the face tiled");
        }
    }
}
