//! A uniform grid over the domain: per cell the domain triangles and the basis families
//! (per domain triangle: the bounding box of its three knot clouds) that may touch it.

use glam::DVec2;

#[derive(Clone, Debug)]
pub(super) struct BoxGrid {
    origin: DVec2,
    inv_cell: f64,
    nx: usize,
    ny: usize,
    /// CSR lists of item ids per cell.
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl BoxGrid {
    /// Items given as bounding boxes; about `target_per_cell` items' worth of area per cell.
    pub(super) fn new(boxes: &[(DVec2, DVec2)]) -> Self {
        let (lo, hi) = boxes.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), (a, b)| (lo.min(*a), hi.max(*b)),
        );
        let extent = (hi - lo).max(DVec2::splat(1e-300));
        let cells_wanted = boxes.len().max(1) as f64;
        let cell = (extent.x * extent.y / cells_wanted)
            .sqrt()
            .max(extent.max_element() / 4096.0);
        let nx = ((extent.x / cell).ceil() as usize).clamp(1, 4096);
        let ny = ((extent.y / cell).ceil() as usize).clamp(1, 4096);
        let inv_cell = 1.0 / cell;
        let mut grid = Self {
            origin: lo,
            inv_cell,
            nx,
            ny,
            starts: Vec::new(),
            items: Vec::new(),
        };
        let mut per_cell: Vec<Vec<u32>> = vec![Vec::new(); nx * ny];
        for (id, (a, b)) in boxes.iter().enumerate() {
            let (x0, y0) = grid.cell_of(*a);
            let (x1, y1) = grid.cell_of(*b);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    per_cell[y * nx + x].push(id as u32);
                }
            }
        }
        grid.starts.push(0);
        for list in per_cell {
            grid.items.extend(list);
            grid.starts.push(grid.items.len() as u32);
        }
        grid
    }

    #[inline]
    fn cell_of(&self, x: DVec2) -> (usize, usize) {
        let c = (x - self.origin) * self.inv_cell;
        let clamp = |v: f64, n: usize| {
            if v.is_nan() || v <= 0.0 {
                0
            } else {
                (v as usize).min(n - 1)
            }
        };
        (clamp(c.x, self.nx), clamp(c.y, self.ny))
    }

    /// The items whose boxes may contain x (a superset; x outside the grid gets the
    /// nearest border cell's list).
    #[inline]
    pub(super) fn candidates(&self, x: DVec2) -> &[u32] {
        let (cx, cy) = self.cell_of(x);
        let c = cy * self.nx + cx;
        &self.items[self.starts[c] as usize..self.starts[c + 1] as usize]
    }
}
