//! Tests of `layout`: flips, splits, crease edges and rim edges.

use super::*;

/// A hexagonal disc of 7 vertices (centre of valence 6) with spoke 0-2 flipped into
/// the other diagonal 1-3 (the centre lost a neighbour), and each vertex landed on a
/// face it is a corner of: (flat data, bad control mesh, landings).
fn disc_with_a_flipped_spoke() -> (TriMesh, TriMesh, Vec<SurfaceParam>) {
    let mut positions = vec![DVec3::ZERO];
    for k in 0..6 {
        let a = std::f64::consts::TAU * k as f64 / 6.0;
        positions.push(DVec3::new(a.cos(), a.sin(), 0.0));
    }
    let ring = |k: u32| 1 + k % 6;
    let fan: Vec<[u32; 3]> = (0..6).map(|k| [0, ring(k), ring(k + 1)]).collect();
    let mut bad = fan.clone();
    bad[0] = [0, 1, 3];
    bad[1] = [1, 2, 3];
    let bad = TriMesh::new(positions.clone(), bad);
    let landing = landed_on_own_faces(&bad);
    (TriMesh::new(positions, fan), bad, landing)
}

fn has_edge(mesh: &TriMesh, a: u32, b: u32) -> bool {
    mesh.triangles
        .iter()
        .any(|t| t.contains(&a) && t.contains(&b))
}

#[test]
fn flips_make_the_centre_regular_and_keep_every_point_landed() {
    let (data, bad_mesh, landing) = disc_with_a_flipped_spoke();
    // Through the flips alone: `improve_layout` would first open vertex 2 (a single
    // face, a Loop corner nobody asked for) by a split.
    let Some(mut net) = Net::new(&data, bad_mesh, &landing, &[]) else {
        panic!("the disc is a manifold");
    };
    let report = net.tidy(&LayoutOptions {
        rounds: 1,
        relax_steps: 0,
        ..Default::default()
    });
    let (mesh, landing, creases) = net.finish();
    assert!(report.flips >= 1);
    // What matters: the centre is regular again (the count of irregular vertices may
    // rise on the rim, where a hexagon's six corners have valence 3, not 4).
    let centre_valence = mesh.triangles.iter().filter(|t| t.contains(&0)).count();
    assert_eq!(centre_valence, 6);
    assert!(has_edge(&mesh, 0, 2));
    assert!(creases.is_empty());
    // All is flat, so every point's landing reproduces it exactly.
    for (p, l) in landing.iter().enumerate() {
        let t = mesh.triangles[l.face as usize].map(|v| mesh.positions[v as usize]);
        let x = t[0] * l.u + t[1] * l.v + t[2] * (1.0 - l.u - l.v);
        assert!(
            x.distance(data.positions[p]) < 1e-12,
            "point {p} landed at {x}"
        );
    }
}

/// Each vertex of `mesh` landed on the first face it is a corner of.
pub(in crate::pipeline::object) fn landed_on_own_faces(mesh: &TriMesh) -> Vec<SurfaceParam> {
    (0..mesh.positions.len() as u32)
        .map(|p| {
            let face = mesh
                .triangles
                .iter()
                .position(|t| t.contains(&p))
                .unwrap_or(0);
            let slot = mesh.triangles[face]
                .iter()
                .position(|&c| c == p)
                .unwrap_or(0);
            SurfaceParam {
                face: face as u32,
                u: f64::from(u8::from(slot == 0)),
                v: f64::from(u8::from(slot == 1)),
            }
        })
        .collect()
}

/// A flat disc where flipping the interior edge a-b (a on the rim with 5 faces, b
/// inside with 6) to c-d lowers the valence deviation (c and d are rim vertices of
/// valence 4 and 3): the flip is refused, as the simplification refuses such an edge,
/// because an interior edge between two rim vertices bridges the data (on a ragged
/// scan rim such edges gave long faces across gaps, chin_tri's surface 4 mm off).
#[test]
fn no_flip_joins_two_rim_vertices_by_an_interior_edge() {
    let at = |x: f64, y: f64| DVec3::new(x, y, 0.0);
    let positions = vec![
        at(-1.0, 0.0), // a
        at(1.0, 0.0),  // b
        at(0.0, 1.0),  // c
        at(0.0, -1.0), // d
        at(-1.5, 1.2),
        at(-2.2, 0.3),
        at(-1.8, -0.8),
        at(1.5, 1.2),
        at(2.2, 0.0),
        at(1.5, -1.2),
    ];
    let triangles = vec![
        [0, 1, 2],
        [1, 0, 3],
        [0, 2, 4],
        [0, 4, 5],
        [0, 5, 6],
        [1, 3, 9],
        [1, 9, 8],
        [1, 8, 7],
        [1, 7, 2],
    ];
    let mesh = TriMesh::new(positions, triangles);
    let landing = landed_on_own_faces(&mesh);
    let Some(mut net) = Net::new(&mesh, mesh.clone(), &landing, &[]) else {
        panic!("the disc is a manifold");
    };
    let rim = net.boundary.clone();
    assert!(rim[0] && !rim[1] && rim[2] && rim[3]);
    net.tidy(&LayoutOptions {
        rounds: 1,
        relax_steps: 0,
        ..Default::default()
    });
    let (tidied, _, _) = net.finish();
    assert!(has_edge(&tidied, 0, 1), "a-b was flipped");
    assert!(!has_edge(&tidied, 2, 3), "c-d bridges the disc");
}

/// The flip that the test above makes is refused when the edge is a crease, and its
/// vertices stay where they are under relaxation.
#[test]
fn crease_edges_are_never_flipped_nor_their_vertices_moved() {
    let (data, bad_mesh, landing) = disc_with_a_flipped_spoke();
    let before = bad_mesh.positions.clone();
    let (mesh, _, creases, _) = improve_layout(
        &data,
        bad_mesh,
        landing,
        &[[3, 1]],
        // Vertex 2, left with one face by the crease, is kept as a corner (not
        // opened by a split of the crease edge).
        &[2],
        &LayoutOptions {
            rounds: 2,
            ..Default::default()
        },
    );
    assert!(has_edge(&mesh, 1, 3), "the crease edge was flipped");
    assert!(!has_edge(&mesh, 0, 2));
    assert_eq!(creases, vec![[1, 3]]);
    assert_eq!(mesh.positions[1], before[1]);
    assert_eq!(mesh.positions[3], before[3]);
}

#[test]
fn a_split_crease_edge_leaves_two_crease_edges() {
    let (data, bad_mesh, landing) = disc_with_a_flipped_spoke();
    let mid = (bad_mesh.positions[1] + bad_mesh.positions[3]) / 2.0;
    let Some(mut net) = Net::new(&data, bad_mesh, &landing, &[[1, 3]]) else {
        panic!("the disc is a manifold");
    };
    assert!(net.split_edge(1, 3, mid));
    let (mesh, _, creases) = net.finish();
    assert_eq!(mesh.positions.len(), 8);
    assert_eq!(creases, vec![[1, 7], [3, 7]]);
}
