//! The Loop limit surface of a regular control net over any set of cells of the
//! three-direction grid: on every cell the quartic box spline of its 12 surrounding
//! control points (the same patches as `box_spline::LatticeSpline`, without its
//! triangular outline). Scans use it so that control points exist only where the data is.
//!
//! Parameters are grid coordinates (x, y): grid vertex (i, j) sits at x = i, y = j, and the
//! plane point of (x, y) is `x a1 + y a2` with a1 = (1, 0), a2 = (1/2, sqrt(3)/2) times the
//! grid spacing. Cell (i, j) "up" is (i,j),(i+1,j),(i,j+1); "down" is (i+1,j),(i+1,j+1),(i,j+1).

use super::bezier::{lattice_points, lattice_triangles};
use super::box_spline::{
    bezier_ordinates, evaluate_ordinates, stencil_values, stencil_weights, STENCIL,
};
use super::{BasisDerivRows, Derivatives, SurfaceParam, TriSurface};
use crate::numeric::floor;
/// Re-exported for the scan domain, which rounds grid coordinates the same way.
pub(crate) use crate::numeric::floor_i64;
use glam::DVec3;
use rayon::prelude::*;

/// A grid cell: lower-left vertex (i, j) and whether it is the down triangle.
pub(crate) type Cell = (i64, i64, bool);

#[derive(Clone, Debug)]
/// The Loop limit surface over cells of the three-direction grid (remeshed scans).
pub struct GridSpline {
    i0: i64,
    j0: i64,
    width: usize,
    height: usize,
    /// Control index of every grid vertex in the bounding box, `u32::MAX` where none.
    index: Vec<u32>,
    coords: Vec<(i64, i64)>,
    cells: Vec<Cell>,
    /// Per cell slot (`cell_slot`): every stencil point exists. Foot-point searches ask
    /// this at every step.
    covered: Vec<bool>,
}

/// The 12 control vertices a cell's patch depends on, in `STENCIL` order.
pub(crate) fn cell_stencil((i, j, down): Cell) -> [(i64, i64); 12] {
    STENCIL.map(|(di, dj)| {
        if down {
            (i + 1 - di, j + 1 - dj)
        } else {
            (i + di, j + dj)
        }
    })
}

/// The cell containing grid point (x, y) and the local coordinates of its up-triangle form.
pub(crate) fn cell_at(x: f64, y: f64) -> (Cell, f64, f64) {
    let (i, j) = (floor(x), floor(y));
    let (fx, fy) = (x - i, y - j);
    let (i, j) = (i as i64, j as i64);
    if fx + fy > 1.0 {
        ((i, j, true), 1.0 - fx, 1.0 - fy)
    } else {
        ((i, j, false), fx, fy)
    }
}

impl GridSpline {
    /// The spline over `cells` (duplicates ignored); its controls are the union of the
    /// cells' stencils, numbered row by row (j, then i) so the order does not depend on
    /// the order of `cells`.
    pub fn new(cells: impl IntoIterator<Item = Cell>) -> Self {
        let mut cells: Vec<Cell> = cells.into_iter().collect();
        cells.sort_unstable_by_key(|&(i, j, d)| (j, i, d));
        cells.dedup();
        let mut lo = (i64::MAX, i64::MAX);
        let mut hi = (i64::MIN, i64::MIN);
        for &c in &cells {
            for (a, b) in cell_stencil(c) {
                lo = (lo.0.min(a), lo.1.min(b));
                hi = (hi.0.max(a), hi.1.max(b));
            }
        }
        if cells.is_empty() {
            lo = (0, 0);
            hi = (-1, -1);
        }
        let width = (hi.0 - lo.0 + 1).max(0) as usize;
        let height = (hi.1 - lo.1 + 1).max(0) as usize;
        let mut used = vec![false; width * height];
        for &c in &cells {
            for (a, b) in cell_stencil(c) {
                used[(b - lo.1) as usize * width + (a - lo.0) as usize] = true;
            }
        }
        let mut index = vec![u32::MAX; width * height];
        let mut coords = Vec::new();
        for (k, _) in used.iter().enumerate().filter(|(_, u)| **u) {
            index[k] = coords.len() as u32;
            coords.push((lo.0 + (k % width) as i64, lo.1 + (k / width) as i64));
        }
        let mut grid = Self {
            i0: lo.0,
            j0: lo.1,
            width,
            height,
            index,
            coords,
            cells,
            covered: Vec::new(),
        };
        grid.covered = (0..2 * width * height)
            .map(|k| {
                let (row, column, down) = (k / 2 / width, k / 2 % width, k % 2 == 1);
                let cell = (grid.i0 + column as i64, grid.j0 + row as i64, down);
                cell_stencil(cell)
                    .iter()
                    .all(|&(a, b)| grid.control_at(a, b).is_some())
            })
            .collect();
        grid
    }

    /// The covered cells.
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// Grid coordinates of every control point, in control order.
    pub fn control_coords(&self) -> &[(i64, i64)] {
        &self.coords
    }

    pub(crate) fn control_at(&self, i: i64, j: i64) -> Option<u32> {
        let (a, b) = (i - self.i0, j - self.j0);
        if a < 0 || b < 0 || a as usize >= self.width || b as usize >= self.height {
            return None;
        }
        let k = self.index[b as usize * self.width + a as usize];
        (k != u32::MAX).then_some(k)
    }

    /// Whether the surface is defined at (x, y): every stencil point of its cell exists.
    pub fn covers(&self, x: f64, y: f64) -> bool {
        if !(x.is_finite() && y.is_finite()) {
            return false;
        }
        let (cell, _, _) = cell_at(x, y);
        self.cell_slot(cell).is_some_and(|k| self.covered[k])
    }

    /// Every cell split into k x k sub-triangles, shared vertices merged: the vertices'
    /// integer coordinates on the grid refined k times (vertex (a, b) sits at grid point
    /// (a / k, b / k)) and the counter-clockwise triangles. Used for resampling (k = 2^L)
    /// and, through `sample_lattice`, for tessellation and curvature sampling.
    pub(crate) fn refined_lattice(&self, k: usize) -> (Vec<(i64, i64)>, Vec<[u32; 3]>) {
        let k = k.max(1);
        let ki = k as i64;
        // Shared vertices found through a dense index over the cells' refined bounding box
        // (a hash map of the coordinates cost ~2 ms per call on a 40k-point scan).
        let (mut lo, mut hi) = ((i64::MAX, i64::MAX), (i64::MIN, i64::MIN));
        for &(i, j, _) in &self.cells {
            lo = (lo.0.min(ki * i), lo.1.min(ki * j));
            hi = (hi.0.max(ki * (i + 1)), hi.1.max(ki * (j + 1)));
        }
        let width = (hi.0 - lo.0 + 1).max(0) as usize;
        let height = (hi.1 - lo.1 + 1).max(0) as usize;
        let mut ids = vec![u32::MAX; width * height];
        let mut coords = Vec::new();
        let mut triangles = Vec::with_capacity(self.cells.len() * k * k);
        let local = lattice_points(k);
        let sub = lattice_triangles(k);
        let mut vid = Vec::with_capacity(local.len());
        for &(i, j, down) in &self.cells {
            // A down cell is the up lattice turned by 180 degrees about the cell's centre.
            vid.clear();
            vid.extend(local.iter().map(|&(a, b)| {
                let key = if down {
                    (ki * (i + 1) - a as i64, ki * (j + 1) - b as i64)
                } else {
                    (ki * i + a as i64, ki * j + b as i64)
                };
                let slot = &mut ids[(key.1 - lo.1) as usize * width + (key.0 - lo.0) as usize];
                if *slot == u32::MAX {
                    *slot = coords.len() as u32;
                    coords.push(key);
                }
                *slot
            }));
            triangles.extend(sub.iter().map(|t| t.map(|x| vid[x as usize])));
        }
        (coords, triangles)
    }

    /// `refined_lattice` with its vertices as surface parameters.
    pub(crate) fn sample_lattice(&self, k: usize) -> (Vec<SurfaceParam>, Vec<[u32; 3]>) {
        let k = k.max(1);
        let (coords, triangles) = self.refined_lattice(k);
        let params = coords
            .into_iter()
            .map(|(a, b)| SurfaceParam {
                face: 0,
                u: a as f64 / k as f64,
                v: b as f64 / k as f64,
            })
            .collect();
        (params, triangles)
    }

    /// Grid triangles whose three corners are all control points: the net the fairness
    /// term smooths.
    pub fn net_triangles(&self) -> Vec<[u32; 3]> {
        let mut out = Vec::new();
        for &(i, j) in &self.coords {
            let ids = [
                self.control_at(i, j),
                self.control_at(i + 1, j),
                self.control_at(i, j + 1),
                self.control_at(i + 1, j + 1),
            ];
            if let (Some(a), Some(b), Some(c)) = (ids[0], ids[1], ids[2]) {
                out.push([a, b, c]);
            }
            if let (Some(b), Some(d), Some(c)) = (ids[1], ids[3], ids[2]) {
                out.push([b, d, c]);
            }
        }
        out
    }
}

/// One control set's Bezier ordinates for every cell of the grid: a foot-point search
/// evaluates each data point's patch several times per round, and 15 ordinates per cell
/// replace the 12 stencil weights through the 15x12 matrix at every evaluation.
pub(crate) struct GridEvaluator<'a> {
    grid: &'a GridSpline,
    controls: &'a [DVec3],
    /// Net index of cell (i, j, down) at `2 * (row * width + column) + down`, over the
    /// controls' bounding box (every cell's corner lies in it); `u32::MAX` for cells not
    /// in the grid's list.
    slot: Vec<u32>,
    nets: Vec<[DVec3; 15]>,
}

impl<'a> GridEvaluator<'a> {
    pub fn new(grid: &'a GridSpline, controls: &'a [DVec3]) -> Self {
        let mut slot = vec![u32::MAX; 2 * grid.width * grid.height];
        let listed: Vec<(usize, Cell)> = grid
            .cells
            .iter()
            .filter_map(|&cell| Some((grid.cell_slot(cell)?, cell)))
            .collect();
        for (n, &(k, _)) in listed.iter().enumerate() {
            slot[k] = n as u32;
        }
        let nets = listed
            .par_iter()
            .with_min_len(256)
            .map(|&(_, cell)| Self::net(grid, controls, cell))
            .collect();
        Self {
            grid,
            controls,
            slot,
            nets,
        }
    }

    /// Missing stencil points count as zero, as `evaluate` drops their weights.
    fn net(grid: &GridSpline, controls: &[DVec3], cell: Cell) -> [DVec3; 15] {
        let stencil = cell_stencil(cell).map(|(a, b)| {
            grid.control_at(a, b)
                .and_then(|id| controls.get(id as usize))
                .copied()
                .unwrap_or(DVec3::ZERO)
        });
        bezier_ordinates(&stencil)
    }

    pub fn evaluate(&self, p: SurfaceParam) -> Derivatives {
        let (cell, lu, lv) = cell_at(p.u, p.v);
        match self.grid.cell_slot(cell).map(|k| self.slot[k]) {
            Some(n) if n != u32::MAX => {
                evaluate_ordinates(&self.nets[n as usize], lu, lv, cell.2, 1.0)
            }
            // A cell outside the list (its stencil may still exist): built on the spot.
            _ => evaluate_ordinates(
                &Self::net(self.grid, self.controls, cell),
                lu,
                lv,
                cell.2,
                1.0,
            ),
        }
    }
}

impl GridSpline {
    /// The quartic Bezier net of `cell` for `controls` (lattice order of degree 4 over the
    /// cell's local coordinates, see `cell_at`; missing stencil points count as zero).
    pub(crate) fn cell_bezier_net(&self, controls: &[DVec3], cell: Cell) -> [DVec3; 15] {
        GridEvaluator::net(self, controls, cell)
    }

    /// Every covered cell's controls (`STENCIL` order), and per cell slot the index of its
    /// stencil in that list (`u32::MAX` where the cell is not covered): what fits whose
    /// rows are all cell stencils (`fit::stencil_matrix`) plan their assembly with.
    pub(crate) fn stencil_table(&self) -> (Vec<[u32; 12]>, Vec<u32>) {
        let mut stencils = Vec::new();
        let of_slot = (0..self.covered.len())
            .map(|k| {
                if !self.covered[k] {
                    return u32::MAX;
                }
                let (row, column, down) = (k / 2 / self.width, k / 2 % self.width, k % 2 == 1);
                let cell = (self.i0 + column as i64, self.j0 + row as i64, down);
                // Covered: every stencil point is a control, so the fallback never applies.
                let ids = cell_stencil(cell).map(|(a, b)| self.control_at(a, b).unwrap_or(0));
                stencils.push(ids);
                (stencils.len() - 1) as u32
            })
            .collect();
        (stencils, of_slot)
    }

    /// The stencil (index into `stencil_table`'s list, via its `of_slot`) and the 12 value
    /// weights at p; `None` where p is not in a covered cell.
    pub(crate) fn stencil_row(&self, of_slot: &[u32], p: SurfaceParam) -> Option<(u32, [f64; 12])> {
        if !(p.u.is_finite() && p.v.is_finite()) {
            return None;
        }
        let (cell, lu, lv) = cell_at(p.u, p.v);
        let g = *of_slot.get(self.cell_slot(cell)?)?;
        (g != u32::MAX).then(|| (g, stencil_values(lu, lv)))
    }

    fn cell_slot(&self, (i, j, down): Cell) -> Option<usize> {
        let (a, b) = (i - self.i0, j - self.j0);
        if a < 0 || b < 0 || a as usize >= self.width || b as usize >= self.height {
            return None;
        }
        Some(2 * (b as usize * self.width + a as usize) + down as usize)
    }
}

impl TriSurface for GridSpline {
    fn control_count(&self) -> usize {
        self.coords.len()
    }

    fn domain_face_count(&self) -> usize {
        self.cells.len()
    }

    /// Outside the covered cells a stencil point may be missing: its weight is dropped
    /// (callers keep parameters inside with `covers` and `step`, so this only guards
    /// against a panic).
    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows) {
        let (cell, lu, lv) = cell_at(p.u, p.v);
        let w = stencil_weights(lu, lv, cell.2, 1.0);
        out.indices.clear();
        out.weights.clear();
        for (k, (a, b)) in cell_stencil(cell).into_iter().enumerate() {
            if let Some(id) = self.control_at(a, b) {
                out.indices.push(id);
                out.weights.push(w[k]);
            }
        }
    }

    /// Without the row buffers of the default: foot-point searches call this millions of
    /// times.
    fn evaluate(&self, controls: &[DVec3], p: SurfaceParam) -> Derivatives {
        let (cell, lu, lv) = cell_at(p.u, p.v);
        let w = stencil_weights(lu, lv, cell.2, 1.0);
        let mut d = Derivatives::default();
        for (k, (a, b)) in cell_stencil(cell).into_iter().enumerate() {
            if let Some(&c) = self
                .control_at(a, b)
                .and_then(|id| controls.get(id as usize))
            {
                d.position += c * w[k][0];
                d.du += c * w[k][1];
                d.dv += c * w[k][2];
                d.duu += c * w[k][3];
                d.duv += c * w[k][4];
                d.dvv += c * w[k][5];
            }
        }
        d
    }

    fn basis_row(&self, p: SurfaceParam, out: &mut Vec<(u32, f64)>) {
        let (cell, lu, lv) = cell_at(p.u, p.v);
        let w = stencil_values(lu, lv);
        out.clear();
        for (k, (a, b)) in cell_stencil(cell).into_iter().enumerate() {
            if let Some(id) = self.control_at(a, b) {
                out.push((id, w[k]));
            }
        }
    }

    fn evaluator<'a>(
        &'a self,
        controls: &'a [DVec3],
    ) -> Box<dyn Fn(SurfaceParam) -> Derivatives + Sync + 'a> {
        let ev = GridEvaluator::new(self, controls);
        Box::new(move |p| ev.evaluate(p))
    }

    /// Moves by (du, dv) as far as the covered cells allow (bisection on the step length).
    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam {
        let at = |t: f64| SurfaceParam {
            face: p.face,
            u: p.u + du * t,
            v: p.v + dv * t,
        };
        if self.covers(p.u + du, p.v + dv) {
            return at(1.0);
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..20 {
            let mid = 0.5 * (lo + hi);
            let q = at(mid);
            if self.covers(q.u, q.v) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        at(lo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::box_spline::LatticeSpline;

    /// On the cells of a triangular lattice the grid spline is the lattice spline.
    #[test]
    fn equals_the_lattice_spline_on_its_cells() {
        let n = 5usize;
        let lattice = LatticeSpline::new(n);
        let mut cells = Vec::new();
        for j in 0..n as i64 {
            for i in 0..n as i64 - j {
                cells.push((i, j, false));
                if i + j + 2 <= n as i64 {
                    cells.push((i, j, true));
                }
            }
        }
        let grid = GridSpline::new(cells);
        assert_eq!(grid.control_count(), lattice.control_count() - 3);
        let height = |i: i64, j: i64| ((i * 7 + j * 13).rem_euclid(5)) as f64 * 0.1;
        let lattice_controls: Vec<DVec3> = lattice_points(lattice.control_segments())
            .into_iter()
            .map(|(a, b)| {
                let (i, j) = (a as i64 - 1, b as i64 - 1);
                DVec3::new(i as f64, j as f64, height(i, j))
            })
            .collect();
        let grid_controls: Vec<DVec3> = grid
            .control_coords()
            .iter()
            .map(|&(i, j)| DVec3::new(i as f64, j as f64, height(i, j)))
            .collect();
        for &(x, y) in &[(0.2, 0.3), (1.7, 2.1), (3.1, 0.4), (0.05, 4.9), (2.5, 1.5)] {
            let a = lattice.evaluate(
                &lattice_controls,
                SurfaceParam {
                    face: 0,
                    u: x / n as f64,
                    v: y / n as f64,
                },
            );
            let b = grid.evaluate(
                &grid_controls,
                SurfaceParam {
                    face: 0,
                    u: x,
                    v: y,
                },
            );
            assert!((a.position - b.position).length() < 1e-12, "({x},{y})");
            assert!((a.du / n as f64 - b.du).length() < 1e-10, "du at ({x},{y})");
            assert!(
                (a.dvv / (n * n) as f64 - b.dvv).length() < 1e-9,
                "dvv at ({x},{y})"
            );
        }
    }

    #[test]
    fn steps_stay_on_covered_cells() {
        let grid = GridSpline::new([(0, 0, false), (0, 0, true), (1, 0, false)]);
        let p = SurfaceParam {
            face: 0,
            u: 0.4,
            v: 0.3,
        };
        assert!(grid.covers(p.u, p.v));
        let q = grid.step(p, 10.0, 0.0);
        assert!(grid.covers(q.u, q.v) && q.u > 1.5 && q.u < 3.0, "{q:?}");
        assert!(!grid.covers(-5.0, 0.5));
        assert!(!grid.covers(f64::NAN, 0.5));
    }

    #[test]
    fn reproduces_planes_with_exact_derivatives() {
        let grid = GridSpline::new((0..4).flat_map(|i| [(i, 0, false), (i, 0, true)]));
        let controls: Vec<DVec3> = grid
            .control_coords()
            .iter()
            .map(|&(i, j)| DVec3::new(i as f64, j as f64, 0.5 * i as f64 - 0.25 * j as f64))
            .collect();
        let e = grid.evaluate(
            &controls,
            SurfaceParam {
                face: 0,
                u: 2.3,
                v: 0.6,
            },
        );
        assert!((e.position - DVec3::new(2.3, 0.6, 0.5 * 2.3 - 0.25 * 0.6)).length() < 1e-12);
        assert!((e.du - DVec3::new(1.0, 0.0, 0.5)).length() < 1e-12);
        assert!((e.dv - DVec3::new(0.0, 1.0, -0.25)).length() < 1e-12);
        assert!(e.duu.length() < 1e-10 && e.duv.length() < 1e-10);
    }
    #[test]
    fn the_per_cell_evaluator_equals_the_stencil_evaluation() {
        let grid = GridSpline::new([(0, 0, false), (0, 0, true), (1, 0, false), (2, 1, true)]);
        let controls: Vec<DVec3> = grid
            .control_coords()
            .iter()
            .map(|&(i, j)| DVec3::new(i as f64, j as f64, ((i * 7 + j * 3) % 5) as f64 * 0.1))
            .collect();
        let fast = grid.evaluator(&controls);
        // Points in listed cells, and one in an unlisted cell whose stencil partly exists.
        for &(x, y) in &[
            (0.2, 0.3),
            (0.7, 0.6),
            (1.25, 0.5),
            (2.9, 1.8),
            (1.5, 1.4),
            (0.1, 0.85),
        ] {
            let p = SurfaceParam {
                face: 0,
                u: x,
                v: y,
            };
            let (a, b) = (grid.evaluate(&controls, p), fast(p));
            let mut row = Vec::new();
            grid.basis_row(p, &mut row);
            let from_row: DVec3 = row.iter().map(|&(i, w)| controls[i as usize] * w).sum();
            assert!((from_row - a.position).length() < 1e-12);
            for (x1, x2) in [
                (a.position, b.position),
                (a.du, b.du),
                (a.dv, b.dv),
                (a.duu, b.duu),
                (a.duv, b.duv),
                (a.dvv, b.dvv),
            ] {
                assert!((x1 - x2).length() < 1e-12, "at ({x}, {y}): {x1} vs {x2}");
            }
        }
    }
}
