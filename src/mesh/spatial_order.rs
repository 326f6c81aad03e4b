//! A mesh renumbered along a space-filling curve (Morton, or Z-order): vertices near each
//! other in space get indices near each other, and so do faces.
//!
//! Why: the stages after reading walk a mesh by its indices while they look up neighbours
//! by position or by adjacency (a simplification's collapses, foot points face by face,
//! normal-matrix rows). In a file's own order, a neighbour is often far away in memory;
//! a scan refined by subdivision stores its edge midpoints after all its old vertices, and
//! a merged or shuffled file is worse. Renumbered, the neighbours share cache lines, and
//! the fit no longer depends on the order the file happened to list its vertices in.

use crate::TriMesh;
use glam::DVec3;

/// Bits per axis of the Morton key (3 * 21 = 63 bits): cells of 2^-21 of the bounding
/// box, far finer than any mesh's vertex spacing, so the key orders all but coincident
/// vertices.
const BITS: u32 = 21;

/// Spreads the low 21 bits of `x` to every third bit.
fn spread(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Each point's Morton key over the points' bounding box.
fn morton_keys(points: &[DVec3]) -> Vec<u64> {
    let (lo, hi) = points
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    let extent = (hi - lo).max_element();
    let cells = f64::from((1u32 << BITS) - 1);
    let scale = if extent > 0.0 && extent.is_finite() {
        cells / extent
    } else {
        0.0
    };
    points
        .iter()
        .map(|p| {
            let q = ((*p - lo) * scale).clamp(DVec3::ZERO, DVec3::splat(cells));
            spread(q.x as u64) | spread(q.y as u64) << 1 | spread(q.z as u64) << 2
        })
        .collect()
}

/// The vertices of `points` in Morton order: `order[new] = old` (ties, such as coincident
/// points, in their old order).
pub fn spatial_order(points: &[DVec3]) -> Vec<u32> {
    let keys = morton_keys(points);
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.sort_by_key(|&v| keys[v as usize]);
    order
}

/// `mesh` with its vertices in Morton order, each face's corners rotated to start at its
/// lowest new index, and the faces sorted by their corners. Rotation keeps a face's cyclic
/// order, so orientation and every adjacency are those of `mesh`; the result depends on
/// the positions and the faces, not on the order the file listed them in.
pub fn spatially_ordered(mesh: &TriMesh) -> TriMesh {
    let order = spatial_order(&mesh.positions);
    let mut new_index = vec![0u32; order.len()];
    for (new, &old) in order.iter().enumerate() {
        new_index[old as usize] = new as u32;
    }
    let positions = order.iter().map(|&v| mesh.positions[v as usize]).collect();
    let mut triangles: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .map(|t| {
            let t = t.map(|v| new_index.get(v as usize).copied().unwrap_or(v));
            let k = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        })
        .collect();
    triangles.sort_unstable();
    TriMesh::new(positions, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: u32) -> TriMesh {
        crate::testdata::height_grid(n, |x, y| 0.1 * x * y)
    }

    /// The same mesh whatever order its vertices came in: a reversed copy renumbers to
    /// the identical mesh.
    #[test]
    fn the_order_follows_the_geometry_not_the_file() {
        let mesh = grid(9);
        let n = mesh.positions.len() as u32;
        let reversed = TriMesh::new(
            mesh.positions.iter().rev().copied().collect(),
            mesh.triangles
                .iter()
                .rev()
                .map(|t| t.map(|v| n - 1 - v))
                .collect(),
        );
        let a = spatially_ordered(&mesh);
        let b = spatially_ordered(&reversed);
        assert_eq!(a, b);
        assert_ne!(a, mesh);
    }

    /// Renumbering keeps every face's corners (by position) and their cyclic order.
    #[test]
    fn faces_keep_their_corners_and_orientation() {
        let mesh = grid(6);
        let ordered = spatially_ordered(&mesh);
        assert_eq!(ordered.triangles.len(), mesh.triangles.len());
        let normal = |m: &TriMesh, t: &[u32; 3]| {
            let p = t.map(|v| m.positions[v as usize]);
            (p[1] - p[0]).cross(p[2] - p[0])
        };
        let mut before: Vec<String> = mesh
            .triangles
            .iter()
            .map(|t| format!("{:?}", normal(&mesh, t)))
            .collect();
        let mut after: Vec<String> = ordered
            .triangles
            .iter()
            .map(|t| format!("{:?}", normal(&ordered, t)))
            .collect();
        before.sort();
        after.sort();
        assert_eq!(before, after);
    }

    /// Neighbours in space end up near each other in index: along the grid's rows the
    /// file order jumps by a row's length between vertically adjacent vertices; Morton
    /// order brings the typical edge's index span down.
    #[test]
    fn edges_span_fewer_indices_after_renumbering() {
        let mesh = grid(63);
        let median_span = |m: &TriMesh| {
            let mut spans: Vec<u32> = m
                .triangles
                .iter()
                .flat_map(|t| {
                    [
                        t[0].abs_diff(t[1]),
                        t[1].abs_diff(t[2]),
                        t[2].abs_diff(t[0]),
                    ]
                })
                .collect();
            spans.sort_unstable();
            spans[spans.len() / 2]
        };
        let (before, after) = (median_span(&mesh), median_span(&spatially_ordered(&mesh)));
        assert!(after * 4 < before, "median edge span {before} -> {after}");
    }

    #[test]
    fn keys_interleave_the_axes() {
        assert_eq!(spread(0b11), 0b1001);
        let keys = morton_keys(&[DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z, DVec3::ONE]);
        assert_eq!(keys[0], 0);
        assert!(keys[1] < keys[2] && keys[2] < keys[3] && keys[3] < keys[4]);
    }
}
