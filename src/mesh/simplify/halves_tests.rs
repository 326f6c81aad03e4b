//! Tests of `halves`: the glued result against one piece, holes and creases across the
//! cut, pinches.

use super::super::tests::{check_result, holed_sheet, torus};
use super::super::{simplify_in_one_piece, SurfaceTopology};
use super::*;
use crate::mesh::distance::MeshDistance;

/// RMS and largest distance of the input's vertices to a simplified mesh, and RMS of
/// their distances to where they landed.
fn errors(input: &TriMesh, out: &Simplified) -> (f64, f64, f64) {
    let query = MeshDistance::new(&out.mesh);
    let d: Vec<f64> = input
        .positions
        .iter()
        .map(|p| query.distance(*p).expect("a distance"))
        .collect();
    let landed: f64 = input
        .positions
        .iter()
        .zip(&out.landing)
        .map(|(p, l)| {
            l.position_on(&out.mesh)
                .expect("a face")
                .distance_squared(*p)
        })
        .sum();
    let n = d.len() as f64;
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let max = d.iter().copied().fold(0.0, f64::max);
    (rms, max, (landed / n).sqrt())
}

/// A bumpy torus of `n x m` quads, so that the quadrics have somewhere to put the
/// vertices.
fn bumpy_torus(n: usize, m: usize) -> TriMesh {
    let mut mesh = torus(n, m);
    for p in &mut mesh.positions {
        let bump = 0.02 * (7.0 * p.x).sin() * (5.0 * p.y).cos() * (9.0 * p.z).sin();
        *p *= 1.0 + bump;
    }
    mesh
}

#[test]
fn halves_glue_into_one_torus_as_close_as_one_piece() {
    let mesh = bumpy_torus(160, 128);
    let opts = SimplifyOptions {
        target_vertices: 600,
        ..Default::default()
    };
    assert!(worth_halving(&mesh, &opts, &[]));
    let topo = Topology::from_mesh(&mesh).expect("manifold");
    let halved = simplify_in_halves(&mesh, &topo, &opts, &[]).expect("split in halves");
    let whole = simplify_in_one_piece(&mesh, &topo, &opts, &[], &[]);
    check_result(&mesh, &halved, &opts);
    assert_eq!(halved.mesh.positions.len(), 600);
    assert_eq!(halved.collapses, mesh.positions.len() - 600);
    let t = SurfaceTopology::of(&halved.mesh).expect("manifold");
    assert_eq!((t.euler, t.genus, t.components), (0, 1, 1));
    // Every kept input vertex maps to a distinct control.
    let mut kept: Vec<u32> = halved
        .control_of
        .iter()
        .copied()
        .filter(|&c| c != REMOVED)
        .collect();
    kept.sort_unstable();
    kept.dedup();
    assert_eq!(kept.len(), 600);
    let (rms, max, landed) = errors(&mesh, &halved);
    let (rms1, max1, landed1) = errors(&mesh, &whole);
    assert!(
        rms <= 1.25 * rms1,
        "RMS {rms:.3e} against {rms1:.3e} in one piece"
    );
    assert!(
        max <= 1.5 * max1,
        "max {max:.3e} against {max1:.3e} in one piece"
    );
    assert!(
        landed <= 1.25 * landed1,
        "landings {landed:.3e} against {landed1:.3e} in one piece"
    );
}

/// A bumpy torus (160 x 128, R = 1, r = 0.4) with crease loops along its outer
/// equator and two meridians (at 45 and 90 degrees), and its crease edges.
fn creased_torus() -> (TriMesh, Vec<[u32; 2]>) {
    let (n, m) = (160, 128);
    let mesh = bumpy_torus(n, m);
    let at = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    let equator = (0..n).map(|i| [at(i, 0), at(i + 1, 0)]);
    let meridians = [20, 40]
        .into_iter()
        .flat_map(|i| (0..m).map(move |j| [at(i, j), at(i, j + 1)]));
    (mesh, equator.chain(meridians).collect())
}

/// Per vertex of `out`, its crease neighbours.
fn crease_degree(out: &Simplified) -> Vec<usize> {
    let mut degree = vec![0; out.mesh.positions.len()];
    for e in &out.crease_edges {
        for &v in e {
            degree[v as usize] += 1;
        }
    }
    degree
}

#[test]
fn crease_loops_across_the_cut_survive_as_chains_on_their_lines() {
    let (mesh, creases) = creased_torus();
    let opts = SimplifyOptions {
        target_vertices: 600,
        ..Default::default()
    };
    assert!(worth_halving(&mesh, &opts, &[]));
    let topo = Topology::from_mesh(&mesh).expect("manifold");
    let halved = simplify_in_halves(&mesh, &topo, &opts, &creases).expect("split in halves");
    let whole = simplify_in_one_piece(&mesh, &topo, &opts, &creases, &[]);
    check_result(&mesh, &halved, &opts);
    assert_eq!(halved.mesh.positions.len(), 600);
    // Every crease edge is an edge of the mesh, and the three loops stay chains: two
    // crease edges at every crease vertex but the two corners where they cross (the
    // meridian at 90 degrees runs along the cut: its edges are boundary edges of both
    // halves).
    let out_topo = Topology::from_mesh(&halved.mesh).expect("manifold");
    let edges: std::collections::HashSet<(u32, u32)> = out_topo
        .edges()
        .into_iter()
        .map(|(a, b, _)| (a.min(b), a.max(b)))
        .collect();
    for &[a, b] in &halved.crease_edges {
        assert!(edges.contains(&(a, b)), "crease edge {a}-{b} is no edge");
    }
    let degree = crease_degree(&halved);
    let corners = degree.iter().filter(|&&d| d == 4).count();
    assert_eq!(corners, 2, "crease corners");
    assert!(degree.iter().all(|&d| [0, 2, 4].contains(&d)), "{degree:?}");
    // The corners are where they were; the other crease vertices are on their lines
    // about as closely as in one piece.
    let input_corners = [(20, 0), (40, 0)].map(|(i, j)| mesh.positions[i * 128 + j]);
    for c in input_corners {
        let kept = halved.mesh.positions.iter().any(|p| p.distance(c) < 1e-12);
        assert!(kept, "corner {c} moved");
    }
    let line = |out: &Simplified| {
        let segments: Vec<[DVec3; 2]> = creases
            .iter()
            .map(|e| e.map(|v| mesh.positions[v as usize]))
            .collect();
        let degree = crease_degree(out);
        let off = |p: DVec3| {
            segments
                .iter()
                .map(|&[a, b]| closest_on_triangle(p, a, b, b).distance(p))
                .fold(f64::INFINITY, f64::min)
        };
        let on_creases = out
            .mesh
            .positions
            .iter()
            .zip(&degree)
            .filter(|(_, &d)| d > 0);
        on_creases.map(|(p, _)| off(*p)).fold(0.0, f64::max)
    };
    let (off, off1) = (line(&halved), line(&whole));
    assert!(
        off <= 1.5 * off1 + 1e-9,
        "{off:.3e} off the lines against {off1:.3e} in one piece"
    );
    let (count, count1) = (halved.crease_edges.len(), whole.crease_edges.len());
    assert!(
        4 * count <= 5 * count1 && 4 * count1 <= 5 * count,
        "{count} crease edges against {count1} in one piece"
    );
}

#[test]
fn a_hole_across_the_cut_keeps_its_rim() {
    let mesh = holed_sheet(150);
    let opts = SimplifyOptions {
        target_vertices: 400,
        ..Default::default()
    };
    let topo = Topology::from_mesh(&mesh).expect("manifold");
    let halved = simplify_in_halves(&mesh, &topo, &opts, &[]).expect("split in halves");
    check_result(&mesh, &halved, &opts);
    assert_eq!(halved.mesh.positions.len(), 400);
    let t = SurfaceTopology::of(&halved.mesh).expect("manifold");
    assert_eq!((t.boundary_loops, t.genus, t.components), (2, 0, 1));
    // The hole (the middle 2 x 2 cells) lies across the median cut: frozen in the
    // halves, so its 8 rim vertices reach the whole mesh's queue, which keeps at
    // least 3 of them (`min_boundary_loop`), on or beside the rim.
    let near_hole = |p: DVec3| {
        let cell = 1.0 / 150.0;
        (p.x - 0.5).abs().max((p.y - 0.5).abs()) <= 1.5 * cell
    };
    let out_topo = Topology::from_mesh(&halved.mesh).expect("manifold");
    let on_hole = (0..halved.mesh.positions.len() as u32)
        .filter(|&v| out_topo.is_boundary(v) && near_hole(halved.mesh.positions[v as usize]))
        .count();
    assert!(on_hole >= 3, "{on_hole} controls on the hole's rim");
}

#[test]
fn faces_alternating_around_a_vertex_are_moved_to_one_side() {
    // A hexagonal fan: its faces alternate sides, so each side's faces form 3 fans.
    let mut positions = vec![DVec3::ZERO];
    for k in 0..6 {
        let a = std::f64::consts::TAU * k as f64 / 6.0;
        positions.push(DVec3::new(a.cos(), a.sin(), 0.0));
    }
    let triangles = (0..6u32).map(|k| [0, 1 + k, 1 + (k + 1) % 6]).collect();
    let mesh = TriMesh::new(positions, triangles);
    let topo = Topology::from_mesh(&mesh).expect("manifold");
    let mut side = vec![0, 1, 0, 1, 0, 1];
    assert!(unpinch(&mesh, &topo, &mut side));
    assert!(side.iter().all(|&s| s == side[0]), "{side:?}");
    // Two runs of faces (one fan per side) are left as they are.
    let mut side = vec![0, 0, 0, 1, 1, 1];
    assert!(unpinch(&mesh, &topo, &mut side));
    assert_eq!(side, vec![0, 0, 0, 1, 1, 1]);
}
