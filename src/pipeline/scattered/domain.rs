//! Domains of the planar-domain kinds over a scan's planar map:
//! - DMS: the cells of the three-direction grid that the map covers (the grid path's
//!   domain, coarser: each triangle carries (n + 1)(n + 2) / 2 controls), made
//!   vertex-manifold, since every boundary vertex of a DMS domain needs one exterior wedge
//!   for its knots;
//! - B-patch: the smallest equilateral triangle around the map (as the single Bezier patch).

use super::error::ScatteredError;
use crate::pipeline::scan::domain::{covered_cells, GridFrame};
use crate::remesh::planar::doubled_area;
use crate::surface::bezier::lattice_len;
use crate::surface::grid_spline::Cell;
use glam::DVec2;
use rustc_hash::{FxHashMap, FxHashSet};

/// A DMS domain on the grid of `spacing` (anchored at the plane's origin).
#[derive(Clone, Debug)]
pub(crate) struct GridTriangulation {
    /// Distance between neighbouring grid vertices in the plane.
    pub spacing: f64,
    /// Domain vertices in the plane.
    pub vertices: Vec<DVec2>,
    /// Counter-clockwise triangles of `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// More domain triangles than this are refused before any knot cloud is built.
pub(crate) const MAX_DMS_TRIANGLES: usize = 400_000;

/// Secant steps of the spacing search (counts move as 1 / spacing^2 plus a rim term).
const SPACING_STEPS: usize = 4;

/// The grid cells covering the map whose DMS spline of `degree` has about `target`
/// controls (never more than 4 % above it when a spacing below exists).
pub(crate) fn dms_domain(
    plane: &[DVec2],
    tris: &[[u32; 3]],
    degree: usize,
    target: usize,
) -> Result<GridTriangulation, ScatteredError> {
    let area: f64 = tris
        .iter()
        .map(|t| 0.5 * doubled_area(plane, t).abs())
        .sum();
    let per_triangle = lattice_len(degree);
    let wanted = (target / per_triangle).max(2) as f64;
    let (lo, hi) = plane.iter().fold(
        (DVec2::splat(f64::MAX), DVec2::splat(f64::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let floor = ((hi - lo).max_element() / 4096.0).max(1e-300);
    // An equilateral grid triangle of side h has area sqrt(3) / 4 h^2.
    let mut h = (area / (0.433 * wanted)).sqrt().max(floor);
    let mut best: Option<(f64, Vec<Cell>)> = None;
    for _ in 0..SPACING_STEPS {
        let cells = manifold_cover(h, plane, tris);
        let count = cells.len().max(1) as f64;
        let fits = count <= 1.04 * wanted;
        if fits || best.is_none() {
            best = Some((h, cells));
        }
        if fits && count >= 0.96 * wanted {
            break;
        }
        h = (h * (count / wanted).sqrt()).max(floor);
    }
    let Some((spacing, cells)) = best else {
        return Err(ScatteredError::EmptyDomain);
    };
    grid_triangulation(spacing, &cells)
}

/// The covering cells of the map on the grid of `spacing`, made vertex-manifold.
pub(crate) fn manifold_cover(spacing: f64, plane: &[DVec2], tris: &[[u32; 3]]) -> Vec<Cell> {
    manifold_cells(covered_cells(&GridFrame { spacing }, plane, tris))
}

/// The triangulation of `cells` on the grid of `spacing` (refused past
/// `MAX_DMS_TRIANGLES`).
pub(crate) fn grid_triangulation(
    spacing: f64,
    cells: &[Cell],
) -> Result<GridTriangulation, ScatteredError> {
    if cells.len() > MAX_DMS_TRIANGLES {
        return Err(ScatteredError::TooManyTriangles {
            triangles: cells.len(),
            limit: MAX_DMS_TRIANGLES,
        });
    }
    if cells.is_empty() {
        return Err(ScatteredError::EmptyDomain);
    }
    let frame = GridFrame { spacing };
    let mut index: FxHashMap<(i64, i64), u32> = FxHashMap::default();
    let mut vertices = Vec::new();
    let triangles = cells
        .iter()
        .map(|&cell| {
            cell_corners(cell).map(|(i, j)| {
                *index.entry((i, j)).or_insert_with(|| {
                    vertices.push(frame.to_plane(i as f64, j as f64));
                    (vertices.len() - 1) as u32
                })
            })
        })
        .collect();
    Ok(GridTriangulation {
        spacing,
        vertices,
        triangles,
    })
}

/// Grid corners of a cell, counter-clockwise: up (i, j), (i + 1, j), (i, j + 1); down
/// (i + 1, j), (i + 1, j + 1), (i, j + 1).
fn cell_corners((i, j, down): Cell) -> [(i64, i64); 3] {
    if down {
        [(i + 1, j), (i + 1, j + 1), (i, j + 1)]
    } else {
        [(i, j), (i + 1, j), (i, j + 1)]
    }
}

/// The six cells around grid vertex (i, j).
fn cells_around((i, j): (i64, i64)) -> [Cell; 6] {
    [
        (i, j, false),
        (i - 1, j, false),
        (i, j - 1, false),
        (i - 1, j, true),
        (i - 1, j - 1, true),
        (i, j - 1, true),
    ]
}

/// Rounds of filling pinched vertices before giving up (each round only adds cells, and a
/// grid region has few pinches: the map's bounding-box cells leave them only at its rim).
const MAX_FILL_ROUNDS: usize = 16;

/// `cells` with every pinched vertex (cells around it in more than one fan) filled with its
/// six cells, so that every boundary vertex has exactly one exterior wedge.
fn manifold_cells(cells: Vec<Cell>) -> Vec<Cell> {
    let mut set: FxHashSet<Cell> = cells.into_iter().collect();
    for _ in 0..MAX_FILL_ROUNDS {
        let vertices: FxHashSet<(i64, i64)> = set.iter().flat_map(|&c| cell_corners(c)).collect();
        let pinched: Vec<(i64, i64)> = vertices
            .into_iter()
            .filter(|&v| fans_around(&set, v) > 1)
            .collect();
        if pinched.is_empty() {
            break;
        }
        for v in pinched {
            set.extend(cells_around(v));
        }
    }
    let mut cells: Vec<Cell> = set.into_iter().collect();
    cells.sort_unstable_by_key(|&(i, j, d)| (j, i, d));
    cells
}

/// Runs of present cells in the cyclic order around a vertex (0 or 1 for a manifold one).
fn fans_around(set: &FxHashSet<Cell>, (i, j): (i64, i64)) -> usize {
    // Counter-clockwise from the up cell having (i, j) as its corner 0.
    let ring: [Cell; 6] = [
        (i, j, false),
        (i - 1, j, true),
        (i - 1, j, false),
        (i - 1, j - 1, true),
        (i, j - 1, false),
        (i, j - 1, true),
    ];
    let present = ring.map(|c| set.contains(&c));
    if present.iter().all(|&p| p) {
        return 1;
    }
    (0..6)
        .filter(|&k| present[k] && !present[(k + 5) % 6])
        .count()
}
