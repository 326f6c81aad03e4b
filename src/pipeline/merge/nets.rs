//! Surface nets (Gibson 1998) over the merged implicit function: one vertex per grid cell
//! the zero set crosses, one quad (two triangles) per grid edge it crosses. Hand-written:
//! the crates that do this take a dense array of samples, and the merged function is only
//! defined in a thin band around the scans (a dense box around a bunny at 1 mm would be
//! 150^3 cells, 30 times the band).

use super::implicit::Implicit;
use super::types::CellKey;
use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// The cell of the merge grid (of size `cell`) holding `p`, saturating far outside the
/// i32 range.
pub(super) fn cell_of(p: DVec3, cell: f64) -> CellKey {
    let q = (p / cell).floor();
    [q.x as i32, q.y as i32, q.z as i32]
}

pub(super) fn corner_position(c: CellKey, cell: f64) -> DVec3 {
    DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) * cell
}

pub(super) fn add(c: CellKey, d: [i32; 3]) -> CellKey {
    [
        c[0].saturating_add(d[0]),
        c[1].saturating_add(d[1]),
        c[2].saturating_add(d[2]),
    ]
}

pub(super) const CORNERS: [[i32; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [0, 1, 0],
    [1, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [0, 1, 1],
    [1, 1, 1],
];

/// The 12 edges of a cell as pairs of `CORNERS` indices.
const EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

/// The 27 offsets of a cell and its neighbours.
pub(super) const NEIGHBOURS: [[i32; 3]; 27] = {
    let mut all = [[0; 3]; 27];
    let mut k = 0;
    while k < 27 {
        all[k] = [
            (k % 3) as i32 - 1,
            ((k / 3) % 3) as i32 - 1,
            (k / 9) as i32 - 1,
        ];
        k += 1;
    }
    all
};

/// The 8 corner values of a cell, if all are defined.
fn cell_values(corners: &FxHashMap<CellKey, f64>, c: CellKey) -> Option<[f64; 8]> {
    let mut v = [0.0; 8];
    for (k, d) in CORNERS.iter().enumerate() {
        v[k] = *corners.get(&add(c, *d))?;
    }
    Some(v)
}

pub(super) fn crossed(corners: &FxHashMap<CellKey, f64>, c: CellKey) -> bool {
    cell_values(corners, c)
        .is_some_and(|v| v.iter().any(|&x| x < 0.0) && v.iter().any(|&x| x >= 0.0))
}

/// The vertex of a crossed cell: the mean of its edges' zero crossings, projected onto
/// the zero set along the function's normal; `None` when the cell is not crossed, too few
/// samples hold the local quadric, the projection ends further than `keep` from every
/// sample, or further than `overhang` beyond the data's rim (`Implicit::overhang`).
pub(super) fn cell_vertex(
    implicit: &Implicit,
    corners: &FxHashMap<CellKey, f64>,
    c: CellKey,
    cell: f64,
    projections: usize,
    keep: f64,
    overhang: f64,
) -> Option<(DVec3, DVec3)> {
    let v = cell_values(corners, c)?;
    let origin = corner_position(c, cell);
    let mut sum = DVec3::ZERO;
    let mut count = 0;
    for (a, b) in EDGES {
        if (v[a] < 0.0) != (v[b] < 0.0) {
            let t = v[a] / (v[a] - v[b]);
            let pa = DVec3::new(
                CORNERS[a][0] as f64,
                CORNERS[a][1] as f64,
                CORNERS[a][2] as f64,
            );
            let pb = DVec3::new(
                CORNERS[b][0] as f64,
                CORNERS[b][1] as f64,
                CORNERS[b][2] as f64,
            );
            sum += pa + (pb - pa) * t;
            count += 1;
        }
    }
    if count == 0 {
        return None;
    }
    let mut x = origin + sum / count as f64 * cell;
    let mut last = implicit.at(x)?;
    for _ in 0..projections {
        x -= last.value * last.normal;
        last = implicit.at(x)?;
    }
    // The plane fits above bring x near the surface, but stand off a curved one by about
    // sigma^2 times the curvature / 2; the quadric takes x onto it. Where too few samples
    // hold a quadric (a corner of the data's rim) the vertex would keep that offset (tens
    // of micrometres at a scan's spacing): it is dropped, the surface stops there.
    x = implicit.refine(x, last.normal)?;
    last = implicit.at(x)?;
    let back = implicit.overhang(x, last.normal)?;
    if back.length() > overhang {
        return None;
    }
    if back != DVec3::ZERO {
        // Beyond the rim by less than `overhang`: the vertex goes onto the tangent plane
        // of the quadric at the rim point nearest to it, where it stands across the rim.
        // Dropped, the surface would stop up to a cell short of the rim, and a crease
        // whose far side the sheet rule leaves out would lose its vertices. Kept on the
        // quadric, it would extrapolate it past the data (on a grazing view of a 5 cm
        // sphere, 340 um inside it half a cell out; the plane stands off it by the square
        // of the gap times the curvature / 2, about 9 um there). Moved onto the rim point
        // itself, the vertices across a stretch of rim would crowd onto it; on the plane
        // each keeps its place (the two measured alike on two synthetic sessions).
        let rim = implicit.refine(x + back, last.normal)?;
        let normal = implicit.at(rim)?.normal;
        let across = -back;
        x = rim + (across - across.dot(normal) * normal);
        last = implicit.at(x)?;
    }
    (last.nearest <= keep && x.is_finite()).then_some((x, last.normal))
}

/// Two triangles per grid edge the zero set crosses whose four cells have vertices,
/// turned so that their normal points where the function grows; in the order of
/// `corner_keys` (built in parallel chunks, joined in order).
pub(super) fn quads(
    corners: &FxHashMap<CellKey, f64>,
    corner_keys: &[CellKey],
    index: &FxHashMap<CellKey, u32>,
    positions: &[DVec3],
) -> Vec<[u32; 3]> {
    let chunks: Vec<Vec<[u32; 3]>> = corner_keys
        .par_chunks(4096)
        .map(|chunk| quads_of(corners, chunk, index, positions))
        .collect();
    chunks.concat()
}

/// `quads` of some corners.
fn quads_of(
    corners: &FxHashMap<CellKey, f64>,
    corner_keys: &[CellKey],
    index: &FxHashMap<CellKey, u32>,
    positions: &[DVec3],
) -> Vec<[u32; 3]> {
    let mut triangles = Vec::new();
    for &c in corner_keys {
        let Some(&fc) = corners.get(&c) else {
            continue;
        };
        for axis in 0..3 {
            let mut step = [0; 3];
            step[axis] = 1;
            let Some(&fd) = corners.get(&add(c, step)) else {
                continue;
            };
            if (fc < 0.0) == (fd < 0.0) {
                continue;
            }
            let (b, e) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut db = [0; 3];
            db[b] = -1;
            let mut de = [0; 3];
            de[e] = -1;
            // Counter-clockwise seen from +axis (e_b x e_e = e_axis).
            let ring = [c, add(c, db), add(add(c, db), de), add(c, de)];
            let Some(mut q) = ring
                .iter()
                .map(|k| index.get(k).copied())
                .collect::<Option<Vec<u32>>>()
            else {
                continue;
            };
            if fc >= 0.0 {
                q.reverse();
            }
            let p = |i: usize| positions[q[i] as usize];
            if p(0).distance(p(2)) <= p(1).distance(p(3)) {
                triangles.push([q[0], q[1], q[2]]);
                triangles.push([q[0], q[2], q[3]]);
            } else {
                triangles.push([q[0], q[1], q[3]]);
                triangles.push([q[1], q[2], q[3]]);
            }
        }
    }
    triangles
}
