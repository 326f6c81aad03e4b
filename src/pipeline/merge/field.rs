//! The merge kept between updates, so that a new, replaced or removed scan recomputes the
//! function and the vertices only around its own samples.
//!
//! A sample changes the function only at corners within the averaging radius of it, and a
//! cell's vertex only through its corners and the samples around the point it is projected
//! from (inside the cell or next to it). So the grid is cut into blocks of `BLOCK` cells;
//! the blocks holding a changed sample and their 26 neighbours are the region, every other
//! cell is at least `BLOCK` cells from a changed sample and keeps its corners and vertex.
//! In the region the candidate cells, corner values and vertices are recomputed exactly as
//! a merge from scratch does, and the mesh is assembled from all cells in key order: the
//! merge of a set of scans is the same whether it was built at once or scan by scan.

use super::holes::close_holes_inside_data;
use super::implicit::{Implicit, PointIndex};
use super::nets::{add, cell_of, cell_vertex, corner_position, crossed, quads, NEIGHBOURS};
use super::types::{CellKey, MergeOptions, Merged, ScanSamples};
use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

/// Side of a block, in cells. It must exceed how far a sample reaches: the averaging
/// radius (`radius_cells`) around a corner, plus the two cells a vertex may sit from its
/// cell's corners while it is projected.
const BLOCK: i32 = 8;
/// Cells a vertex's projection reaches beyond the averaging radius (see `BLOCK`).
const PROJECTION_REACH_CELLS: f64 = 2.0;

/// The merge grid's state: which cells hold samples, the function at the corners of the
/// cells the surface may cross, and each such cell's vertex.
#[derive(Clone, Debug, Default)]
pub struct MergeField {
    cell: f64,
    /// Samples per cell (of every scan merged).
    occupancy: FxHashMap<CellKey, u32>,
    /// Cells next to a sample (the candidates) and their vertex, if the surface crosses
    /// them inside the data.
    candidates: FxHashMap<CellKey, Option<(DVec3, DVec3)>>,
    /// The function at the candidates' corners, where it is defined.
    corners: FxHashMap<CellKey, f64>,
}

fn block_of(c: CellKey) -> CellKey {
    [
        c[0].div_euclid(BLOCK),
        c[1].div_euclid(BLOCK),
        c[2].div_euclid(BLOCK),
    ]
}

/// `blocks` and their 26 neighbours.
fn dilated(blocks: &FxHashSet<CellKey>) -> FxHashSet<CellKey> {
    blocks
        .iter()
        .flat_map(|b| NEIGHBOURS.iter().map(move |d| add(*b, *d)))
        .collect()
}

/// The cells `c + d` for every cell `c` of `sorted` (sorted, without repeats) and every
/// `d` in `steps` along each axis in turn (`[-1, 0, 1]`: the 27 neighbours; `[0, 1]`: the
/// 8 corners), sorted and without repeats. A constant shift along one axis keeps the
/// order of the keys, so each axis is a merge of sorted copies: linear, with no hashing or
/// sorting (inserting each occupied cell's 27 neighbours into a hash set took a tenth to a
/// sixth of the bunny session's merges).
fn dilated_cells(sorted: &[CellKey], steps: &[i32]) -> Vec<CellKey> {
    let mut cells = sorted.to_vec();
    for axis in 0..3 {
        cells = merge_shifted(&cells, axis, steps);
    }
    cells
}

/// The union of `sorted` shifted by each of `steps` along `axis`, sorted, without repeats.
fn merge_shifted(sorted: &[CellKey], axis: usize, steps: &[i32]) -> Vec<CellKey> {
    let shifted = |k: usize, i: usize| {
        let mut c = sorted[i];
        c[axis] = c[axis].saturating_add(steps[k]);
        c
    };
    let mut at = vec![0usize; steps.len()];
    let mut out: Vec<CellKey> = Vec::with_capacity(sorted.len() * 2);
    loop {
        let next = (0..steps.len())
            .filter(|&k| at[k] < sorted.len())
            .map(|k| shifted(k, at[k]))
            .min();
        let Some(next) = next else {
            return out;
        };
        if out.last() != Some(&next) {
            out.push(next);
        }
        for (k, i) in at.iter_mut().enumerate() {
            if *i < sorted.len() && shifted(k, *i) == next {
                *i += 1;
            }
        }
    }
}

impl MergeField {
    /// An empty field on a grid of cell size `cell`.
    pub fn new(cell: f64) -> Self {
        Self {
            cell,
            ..Default::default()
        }
    }

    /// The grid's cell size.
    pub fn cell(&self) -> f64 {
        self.cell
    }

    /// Whether no sample has been merged.
    pub fn is_empty(&self) -> bool {
        self.occupancy.is_empty()
    }

    /// The merge of `scans` (every scan merged now) after `added` joined them and
    /// `removed` left: recomputed only in the blocks around the samples of `added` and
    /// `removed` (everywhere when the field is empty or the options reach further than a
    /// block). The result equals `merge(scans, ..)`.
    pub fn update(
        &mut self,
        scans: &[&ScanSamples],
        added: &[&ScanSamples],
        removed: &[&ScanSamples],
        opts: &MergeOptions,
    ) -> Merged {
        let cell = self.cell;
        let whole = self.occupancy.is_empty()
            || opts.radius_cells + PROJECTION_REACH_CELLS >= BLOCK as f64
            || opts.radius_cells.is_nan();
        let mut core: FxHashSet<CellKey> = FxHashSet::default();
        for (scan, step) in removed
            .iter()
            .map(|s| (s, -1i64))
            .chain(added.iter().map(|s| (s, 1)))
        {
            for p in &scan.points {
                let c = cell_of(*p, cell);
                core.insert(block_of(c));
                let count = self.occupancy.entry(c).or_default();
                *count = (*count as i64 + step).max(0) as u32;
                if *count == 0 {
                    self.occupancy.remove(&c);
                }
            }
        }
        let region = (!whole).then(|| dilated(&core));
        let near_region = region.as_ref().map(dilated);
        let in_region = |c: CellKey| region.as_ref().is_none_or(|r| r.contains(&block_of(c)));
        let near = |c: CellKey| {
            near_region
                .as_ref()
                .is_none_or(|r| r.contains(&block_of(c)))
        };
        self.candidates.retain(|c, _| !in_region(*c));
        self.corners.retain(|c, _| !in_region(*c));

        let mut occupied: Vec<CellKey> = self
            .occupancy
            .keys()
            .copied()
            .filter(|o| near(*o))
            .collect();
        occupied.par_sort_unstable();
        let mut fresh = dilated_cells(&occupied, &[-1, 0, 1]);
        fresh.retain(|c| in_region(*c));
        // The region's corners of its own candidates and of the kept ones beside it.
        let mut cells: Vec<CellKey> = self
            .candidates
            .keys()
            .copied()
            .filter(|c| near(*c))
            .chain(fresh.iter().copied())
            .collect();
        cells.par_sort_unstable();
        let mut corner_keys = dilated_cells(&cells, &[0, 1]);
        drop(cells);
        corner_keys.retain(|c| in_region(*c));

        let radius = opts.radius_cells * cell;
        let index = PointIndex::build(scans, radius);
        let implicit = Implicit {
            index: &index,
            radius,
            sigma: opts.sigma_cells * cell,
        };
        let values: Vec<Option<f64>> = corner_keys
            .par_iter()
            .with_min_len(512)
            .map(|c| implicit.at(corner_position(*c, cell)).map(|s| s.value))
            .collect();
        self.corners.extend(
            corner_keys
                .iter()
                .zip(&values)
                .filter_map(|(c, v)| v.map(|v| (*c, v))),
        );
        let keep = opts.keep_cells * cell;
        let overhang = opts.rim_overhang_cells * cell;
        let corners = &self.corners;
        let vertices: Vec<Option<(DVec3, DVec3)>> = fresh
            .par_iter()
            .with_min_len(256)
            .map(|c| {
                cell_vertex(
                    &implicit,
                    corners,
                    *c,
                    cell,
                    opts.projections,
                    keep,
                    overhang,
                )
            })
            .collect();
        self.candidates.extend(fresh.iter().copied().zip(vertices));
        let mut merged = self.assemble();
        if opts.close_holes {
            merged.closed_holes = close_holes_inside_data(&mut merged.mesh, &implicit);
        }
        merged.corners_evaluated = corner_keys.len();
        merged.recomputed_cells = fresh.len();
        merged
    }

    /// The mesh of every candidate's vertex, in cell order (as a merge from scratch).
    fn assemble(&self) -> Merged {
        let mut cells: Vec<(&CellKey, &Option<(DVec3, DVec3)>)> = self.candidates.iter().collect();
        cells.par_sort_unstable_by_key(|(c, _)| **c);
        let mut merged = Merged {
            cell: self.cell,
            ..Default::default()
        };
        let mut index: FxHashMap<CellKey, u32> = FxHashMap::default();
        for (c, v) in cells {
            match v {
                Some((p, n)) => {
                    index.insert(*c, merged.mesh.positions.len() as u32);
                    merged.mesh.positions.push(*p);
                    merged.normals.push(*n);
                    merged.cells.push(*c);
                }
                None if crossed(&self.corners, *c) => merged.dropped_vertices += 1,
                None => {}
            }
        }
        let mut corner_keys: Vec<CellKey> = self.corners.keys().copied().collect();
        corner_keys.par_sort_unstable();
        merged.mesh.triangles = quads(&self.corners, &corner_keys, &index, &merged.mesh.positions);
        merged
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The merged shifts hold exactly the cells a hash set of every cell's offsets holds,
    /// in order, with saturation at the end of the key range.
    #[test]
    fn dilated_cells_are_every_offset_cell_once_in_order() {
        let mut seed = 5u64;
        let mut next = || (crate::testdata::uniform(&mut seed) * 12.0) as i32 - 6;
        let mut cells: Vec<CellKey> = (0..300).map(|_| [next(), next(), next()]).collect();
        cells.push([i32::MAX, 0, i32::MIN]);
        cells.sort_unstable();
        cells.dedup();
        for steps in [&[-1, 0, 1][..], &[0, 1][..]] {
            let got = dilated_cells(&cells, steps);
            let mut want: Vec<CellKey> = cells
                .iter()
                .flat_map(|c| {
                    steps.iter().flat_map(move |&a| {
                        steps
                            .iter()
                            .flat_map(move |&b| steps.iter().map(move |&d| add(*c, [a, b, d])))
                    })
                })
                .collect::<FxHashSet<CellKey>>()
                .into_iter()
                .collect();
            want.sort_unstable();
            assert_eq!(got, want, "steps {steps:?}");
        }
        assert!(dilated_cells(&[], &[-1, 0, 1]).is_empty());
    }
}
