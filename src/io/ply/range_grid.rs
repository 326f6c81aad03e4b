//! Triangles of a Stanford range image: the grid cells are the connectivity.

use crate::io::RangeGrid;

/// Triangulates a range image: each full 2x2 cell is split on its shorter diagonal, a cell
/// with three points gives one triangle, and triangles with an edge longer than
/// `max_edge_factor` times the median grid spacing (depth jumps) are dropped.
pub(crate) fn triangulate_range_grid(
    grid: &RangeGrid,
    cells: &[Option<u32>],
    max_edge_factor: f64,
) -> Vec<[u32; 3]> {
    // Rows or columns of zero (with the other up to 2^32) hold no cell: nothing to walk.
    if grid.points.is_empty() {
        return Vec::new();
    }
    let at = |r: usize, c: usize| cells[r * grid.cols + c];
    let pos = |r: usize, c: usize| grid.points[r * grid.cols + c];
    let mut spacing = Vec::new();
    for r in 0..grid.rows {
        for c in 0..grid.cols {
            if let Some(p) = pos(r, c) {
                if c + 1 < grid.cols {
                    if let Some(q) = pos(r, c + 1) {
                        spacing.push((p - q).length());
                    }
                }
                if r + 1 < grid.rows {
                    if let Some(q) = pos(r + 1, c) {
                        spacing.push((p - q).length());
                    }
                }
            }
        }
    }
    if spacing.is_empty() {
        return Vec::new();
    }
    let mid = spacing.len() / 2;
    let median = *spacing.select_nth_unstable_by(mid, f64::total_cmp).1;
    let max_edge = median * max_edge_factor;
    let mut tris = Vec::new();
    let mut push = |a: (usize, usize), b: (usize, usize), c: (usize, usize)| {
        if let (Some(ia), Some(ib), Some(ic), Some(pa), Some(pb), Some(pc)) = (
            at(a.0, a.1),
            at(b.0, b.1),
            at(c.0, c.1),
            pos(a.0, a.1),
            pos(b.0, b.1),
            pos(c.0, c.1),
        ) {
            if (pa - pb).length() <= max_edge
                && (pb - pc).length() <= max_edge
                && (pc - pa).length() <= max_edge
            {
                tris.push([ia, ib, ic]);
            }
        }
    };
    for r in 0..grid.rows.saturating_sub(1) {
        for c in 0..grid.cols.saturating_sub(1) {
            // Corners counter-clockwise in (col, row): a=(r,c) b=(r,c+1) d=(r+1,c+1) e=(r+1,c).
            let (a, b, d, e) = ((r, c), (r, c + 1), (r + 1, c + 1), (r + 1, c));
            let present = [a, b, d, e]
                .iter()
                .filter(|&&(r, c)| at(r, c).is_some())
                .count();
            match present {
                4 => {
                    let diag_ad = (pos(a.0, a.1).unwrap_or_default()
                        - pos(d.0, d.1).unwrap_or_default())
                    .length();
                    let diag_be = (pos(b.0, b.1).unwrap_or_default()
                        - pos(e.0, e.1).unwrap_or_default())
                    .length();
                    if diag_ad <= diag_be {
                        push(a, b, d);
                        push(a, d, e);
                    } else {
                        push(a, b, e);
                        push(b, d, e);
                    }
                }
                3 => {
                    let ring = [a, b, d, e];
                    let corners: Vec<(usize, usize)> = ring
                        .iter()
                        .copied()
                        .filter(|&(r, c)| at(r, c).is_some())
                        .collect();
                    push(corners[0], corners[1], corners[2]);
                }
                _ => {}
            }
        }
    }
    tris
}
