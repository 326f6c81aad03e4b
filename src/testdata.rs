//! Locating the third-party test data in `../shared/data` (never committed here), and the
//! small generated shapes that tests and examples share.

use crate::TriMesh;
use glam::DVec3;
use std::path::PathBuf;

/// xorshift in [0, 1): reproducible random numbers for tests, without a dependency.
pub fn uniform(seed: &mut u64) -> f64 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed >> 11) as f64 / (1u64 << 53) as f64
}

/// Path of a file under `../shared/data`, or `None` when the folder is absent so that a
/// test can skip. With `TRISPLINE_REQUIRE_DATA=1` (set by `.ci/run`) a missing file panics
/// instead: CI must never pass by skipping.
pub fn shared_data(relative: &str) -> Option<PathBuf> {
    let root = std::env::var_os("TRISPLINE_DATA_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let path = root.join(relative);
    if path.exists() {
        return Some(path);
    }
    if std::env::var("TRISPLINE_REQUIRE_DATA").is_ok_and(|v| v == "1") {
        panic!("TRISPLINE_REQUIRE_DATA=1 but {} is missing", path.display());
    }
    eprintln!("skipping: {} not found", path.display());
    None
}

/// Every Stanford range scan in the shared data, relative to its root: the raw and the
/// registered views, the range grid and MeshLab's triangulation (the scans the coverage
/// goal is measured on).
pub const STANFORD_SCANS: [&str; 10] = [
    "range_scans/bun000_tri.ply",
    "range_scans/bun045_tri.ply",
    "range_scans/chin_tri.ply",
    "range_scans/bun000_range_grid.ply",
    "range_scans/bun000_meshlab_triangulated.ply",
    "range_scans/registered/bun000.ply",
    "range_scans/registered/bun045.ply",
    "range_scans/registered/bun180.ply",
    "range_scans/registered/bun270.ply",
    "range_scans/registered/chin.ply",
];

/// The octahedron with vertices +x, -x, +y, -y, +z, -z (in that order), faces
/// counter-clockwise seen from outside: the smallest closed mesh with vertices of valence 4
/// and an edge loop (0-2-1-3) around its middle.
pub fn octahedron() -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let vertices = vec![
        DVec3::X,
        -DVec3::X,
        DVec3::Y,
        -DVec3::Y,
        DVec3::Z,
        -DVec3::Z,
    ];
    let faces = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    (vertices, faces)
}

/// The regular icosahedron with vertices (0, +-1, +-t) and their cyclic permutations (t the
/// golden ratio), faces counter-clockwise seen from outside: the closed valence-5 mesh the
/// Loop tests, benches and generated shapes start from.
pub fn icosahedron() -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let vertices = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .map(|(x, y, z)| DVec3::new(x, y, z));
    let faces = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    (vertices.to_vec(), faces)
}

/// The unit square as a height field: `n` x `n` cells, vertex (i, j) at (x, y) = (i/n, j/n)
/// lifted to `height(x, y)`, row by row, two triangles per cell split along the diagonal
/// from (i, j) to (i+1, j+1), counter-clockwise seen from above.
pub fn height_grid(n: u32, height: impl Fn(f64, f64) -> f64) -> TriMesh {
    let at = |i: u32, j: u32| j * (n + 1) + i;
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (f64::from(i) / f64::from(n), f64::from(j) / f64::from(n));
            positions.push(DVec3::new(x, y, height(x, y)));
        }
    }
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in 0..n {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    TriMesh::new(positions, triangles)
}

/// A closed prism over a regular polygon of `sides` sides (radius 1, height 2), its sides
/// a fine grid (`rows` rows of rectangles split in two, `per_side` across each side) and
/// its caps fans from a centre vertex, outward oriented; and its sharp edges (the two rims
/// and the vertical edges), each as the chain of mesh edges along it. A faceted part whose
/// flat sides a simplification can only keep exactly with long thin faces.
pub fn faceted_prism(sides: usize, rows: usize, per_side: usize) -> (TriMesh, Vec<[u32; 2]>) {
    let around = sides * per_side;
    let corner = |k: usize| {
        let a = std::f64::consts::TAU * k as f64 / sides as f64;
        DVec3::new(a.cos(), a.sin(), 0.0)
    };
    let ring_point = |j: usize| {
        let (side, step) = (j / per_side, j % per_side);
        let t = step as f64 / per_side as f64;
        corner(side) * (1.0 - t) + corner(side + 1) * t
    };
    let mut positions = Vec::new();
    for r in 0..=rows {
        let z = 2.0 * r as f64 / rows as f64 - 1.0;
        positions.extend((0..around).map(|j| ring_point(j) + DVec3::Z * z));
    }
    let at = |r: usize, j: usize| (r * around + j % around) as u32;
    let mut triangles = Vec::new();
    for r in 0..rows {
        for j in 0..around {
            let (a, b, c, d) = (at(r, j), at(r, j + 1), at(r + 1, j + 1), at(r + 1, j));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    let bottom = positions.len() as u32;
    positions.push(-DVec3::Z);
    let top = positions.len() as u32;
    positions.push(DVec3::Z);
    for j in 0..around {
        triangles.push([bottom, at(0, j + 1), at(0, j)]);
        triangles.push([top, at(rows, j), at(rows, j + 1)]);
    }
    let mut creases = Vec::new();
    for j in 0..around {
        creases.push([at(0, j), at(0, j + 1)]);
        creases.push([at(rows, j), at(rows, j + 1)]);
    }
    for side in 0..sides {
        for r in 0..rows {
            creases.push([at(r, side * per_side), at(r + 1, side * per_side)]);
        }
    }
    (TriMesh::new(positions, triangles), creases)
}

/// A torus (radii 1 and 0.35) on an `n x m` grid, its quads split along alternating
/// diagonals: a closed genus-1 mesh without subdivision connectivity, so the worker fits
/// it on the object path.
pub fn torus(n: usize, m: usize) -> TriMesh {
    torus_grid(n, m, |i, j| (i + j) % 2 == 0)
}

/// The same torus with every quad split along one diagonal: valence 6 everywhere, so every
/// face of it as a Loop control mesh is a box-spline patch.
pub fn regular_torus(n: usize, m: usize) -> TriMesh {
    torus_grid(n, m, |_, _| true)
}

/// The torus grid, quad (i, j) split along (i, j)-(i+1, j+1) where `along_first` says so.
fn torus_grid(n: usize, m: usize, along_first: impl Fn(usize, usize) -> bool) -> TriMesh {
    use std::f64::consts::TAU;
    let mut positions = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (a, b) = (TAU * i as f64 / n as f64, TAU * j as f64 / m as f64);
            let r = 1.0 + 0.35 * b.cos();
            positions.push(DVec3::new(r * a.cos(), r * a.sin(), 0.35 * b.sin()));
        }
    }
    let at = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..m {
            if along_first(i, j) {
                triangles.push([at(i, j), at(i + 1, j), at(i, j + 1)]);
                triangles.push([at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
            } else {
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            }
        }
    }
    TriMesh::new(positions, triangles)
}
