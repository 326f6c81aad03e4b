//! Cleaning hand-made broken meshes and the real scans into manifold, oriented meshes.

use glam::DVec3;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::stats::mesh_stats;
use trispline::mesh::topology::Topology;
use trispline::testdata::shared_data;
use trispline::TriMesh;

use crate::mesh_roundtrip::octahedron;

fn p(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

#[test]
fn pinch_vertex_is_split_into_two_fans() {
    // Two triangles touching only at vertex 0.
    let m = TriMesh::new(
        vec![
            p(0., 0., 0.),
            p(1., 0., 0.),
            p(1., 1., 0.),
            p(-1., 0., 0.),
            p(-1., -1., 0.),
        ],
        vec![[0, 1, 2], [0, 3, 4]],
    );
    assert!(Topology::from_mesh(&m).is_err());
    assert_eq!(mesh_stats(&m, 0).non_manifold_vertices, 1);
    let c = clean(&m, &CleanOptions::default());
    assert_eq!(c.report.pinch_vertices_split, 1);
    assert_eq!(c.mesh.positions.len(), 6);
    assert!(Topology::from_mesh(&c.mesh).is_ok());
    assert_eq!(c.original_vertex.iter().filter(|&&o| o == 0).count(), 2);
}

#[test]
fn three_faces_on_one_edge_become_manifold() {
    let m = TriMesh::new(
        vec![
            p(0., 0., 0.),
            p(1., 0., 0.),
            p(0.5, 1., 0.),
            p(0.5, -1., 0.),
            p(0.5, 0., 1.),
        ],
        vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
    );
    let s = mesh_stats(&m, 0);
    assert_eq!(s.non_manifold_edges, 1);
    let c = clean(&m, &CleanOptions::default());
    assert_eq!(c.report.non_manifold_edges_split, 1);
    assert_eq!(mesh_stats(&c.mesh, 0).non_manifold_edges, 0);
    assert!(Topology::from_mesh(&c.mesh).is_ok());
}

#[test]
fn duplicates_degenerates_and_orientation() {
    let m = TriMesh::new(
        vec![
            p(0., 0., 0.),
            p(1., 0., 0.),
            p(1., 1., 0.),
            p(0., 1., 0.),
            p(2., 0., 0.),
            p(0., 0., 0.),
        ],
        // face 1 is flipped relative to face 0; face 2 duplicates face 0 (rotated);
        // face 3 is degenerate (collinear); vertex 5 duplicates vertex 0 exactly.
        vec![[0, 1, 2], [0, 3, 2], [1, 2, 0], [0, 1, 4], [5, 2, 3]],
    );
    let c = clean(&m, &CleanOptions::default());
    assert_eq!(c.report.welded_vertices, 1);
    assert_eq!(c.report.degenerate_faces_removed, 1);
    // [5,2,3] welds to [0,2,3], the same vertex set as [0,3,2]: a duplicate too.
    assert_eq!(c.report.duplicate_faces_removed, 2);
    assert_eq!(c.report.faces_flipped, 1);
    assert_eq!(c.mesh.triangles.len(), 2);
    assert!(Topology::from_mesh(&c.mesh).is_ok());
    // Both faces now share edge (0, 2) in opposite directions: normals agree.
    let n = |t: [u32; 3]| {
        let q = |i: u32| c.mesh.positions[i as usize];
        (q(t[1]) - q(t[0])).cross(q(t[2]) - q(t[0])).z.signum()
    };
    assert_eq!(n(c.mesh.triangles[0]), n(c.mesh.triangles[1]));
}

#[test]
fn a_zero_thickness_fin_goes_and_leaves_the_body_closed() {
    // A fin of two coinciding faces, one the other's reverse, standing on the edge (+x, +z):
    // the flat remains of a thin part a volumetric reconstruction collapsed. Keeping one
    // side of it gives that edge three faces.
    let mut m = octahedron();
    m.positions.push(p(1.5, 0.2, 1.5));
    m.triangles.push([0, 4, 6]);
    m.triangles.push([4, 0, 6]);
    let c = clean(&m, &CleanOptions::default());
    assert_eq!(c.report.sheet_faces_removed, 2);
    assert_eq!(c.report.duplicate_faces_removed, 0);
    assert_eq!(c.report.non_manifold_edges_split, 0);
    assert_eq!(c.mesh.triangles.len(), 8);
    assert_eq!(c.mesh.positions.len(), 6);
    let topo = Topology::from_mesh(&c.mesh).expect("manifold");
    assert!(topo.boundary.iter().all(|&b| !b), "the body stays closed");
}

#[test]
fn a_lone_double_sided_sheet_keeps_one_side() {
    // A square exported double-sided for rendering: both sides of each triangle. Nothing
    // surrounds it, so one side stays (dropping both would leave nothing).
    let corners = vec![p(0., 0., 0.), p(1., 0., 0.), p(1., 1., 0.), p(0., 1., 0.)];
    let m = TriMesh::new(corners, vec![[0, 1, 2], [0, 2, 3], [2, 1, 0], [3, 2, 0]]);
    let c = clean(&m, &CleanOptions::default());
    assert_eq!(c.report.sheet_faces_removed, 0);
    assert_eq!(c.report.duplicate_faces_removed, 2);
    assert_eq!(c.mesh.triangles.len(), 2);
    let topo = Topology::from_mesh(&c.mesh).expect("manifold");
    assert_eq!(topo.boundary.iter().filter(|&&b| b).count(), 4);
}

#[test]
fn the_face_between_two_touching_bodies_goes() {
    // Two tetrahedra on one base triangle, one above and one below, each closed with its
    // own copy of the base in its own orientation: a membrane inside their union. Both
    // copies go, and the six side faces close one surface (a bipyramid).
    let m = TriMesh::new(
        vec![
            p(0., 0., 0.),
            p(1., 0., 0.),
            p(0., 1., 0.),
            p(0.3, 0.3, 1.),
            p(0.3, 0.3, -1.),
        ],
        vec![
            [0, 2, 1],
            [0, 1, 3],
            [1, 2, 3],
            [2, 0, 3],
            [0, 1, 2],
            [1, 0, 4],
            [2, 1, 4],
            [0, 2, 4],
        ],
    );
    let c = clean(&m, &CleanOptions::default());
    assert_eq!(c.report.sheet_faces_removed, 2);
    assert_eq!(c.report.non_manifold_edges_split, 0);
    assert_eq!(c.mesh.triangles.len(), 6);
    let topo = Topology::from_mesh(&c.mesh).expect("manifold");
    assert!(topo.boundary.iter().all(|&b| !b), "the union is closed");
}

#[test]
fn two_closed_bodies_touching_along_an_edge_are_parted_without_holes() {
    // Two octahedra meeting along one edge (the first's +x..+z is the second's -x..-z):
    // four faces on that edge, two of each body. Each body's fans around the edge's ends
    // hold its own two faces, so both ends are split and both bodies stay closed.
    let a = octahedron();
    let shifted = a.positions.iter().map(|q| *q + p(1., 0., 1.));
    let mut positions = a.positions.clone();
    positions.extend(shifted);
    let mut triangles = a.triangles.clone();
    triangles.extend(a.triangles.iter().map(|t| t.map(|v| v + 6)));
    let c = clean(
        &TriMesh::new(positions, triangles),
        &CleanOptions::default(),
    );
    assert_eq!(c.report.welded_vertices, 2);
    assert_eq!(c.report.non_manifold_edges_split, 1);
    assert_eq!(c.report.pinch_vertices_split, 2);
    assert_eq!(c.mesh.triangles.len(), 16);
    assert_eq!(c.mesh.positions.len(), 12);
    let topo = Topology::from_mesh(&c.mesh).expect("manifold");
    assert!(topo.boundary.iter().all(|&b| !b), "both bodies stay closed");
}

#[test]
fn moebius_strip_is_reported_non_orientable() {
    let k = 8;
    let mut pos = Vec::new();
    for i in 0..k {
        let a = std::f64::consts::TAU * i as f64 / k as f64;
        let twist = a / 2.0;
        for s in [-0.3, 0.3] {
            let r = 1.0 + s * twist.cos();
            pos.push(p(r * a.cos(), r * a.sin(), s * twist.sin()));
        }
    }
    let mut tris = Vec::new();
    for i in 0..k as u32 {
        let (a, b) = (2 * i, 2 * i + 1);
        let (c, d) = if i + 1 < k as u32 {
            (2 * i + 2, 2 * i + 3)
        } else {
            (1, 0)
        };
        tris.push([a, c, b]);
        tris.push([b, c, d]);
    }
    let c = clean(&TriMesh::new(pos, tris), &CleanOptions::default());
    assert_eq!(c.report.non_orientable_components, 1);
}

#[test]
fn tolerance_weld_merges_near_vertices() {
    let m = TriMesh::new(
        vec![
            p(0., 0., 0.),
            p(1., 0., 0.),
            p(0., 1., 0.),
            p(1e-9, 1., 0.),
            p(1., 0., 0.),
            p(1., 1., 0.),
        ],
        vec![[0, 1, 2], [3, 4, 5]],
    );
    // Exact welding joins the two copies of (1, 0, 0) only: the faces then touch at that one
    // vertex, a pinch, which is split again (6 vertices).
    let exact = clean(&m, &CleanOptions::default());
    assert_eq!(exact.mesh.positions.len(), 6);
    let loose = clean(
        &m,
        &CleanOptions {
            weld_tolerance: Some(1e-6),
        },
    );
    assert_eq!(loose.mesh.positions.len(), 4);
}

#[test]
fn real_scans_clean_into_manifold_meshes() {
    for rel in [
        "range_scans/bun000_tri.ply",
        "range_scans/bun045_tri.ply",
        "range_scans/chin_tri.ply",
        "range_scans/bun000_meshlab_triangulated.ply",
        "models/bun_zipper_res4.ply",
    ] {
        let Some(path) = shared_data(rel) else { return };
        let mesh = read_mesh_file(&path, &LoadOptions::default())
            .expect("loads")
            .mesh;
        let c = clean(&mesh, &CleanOptions::default());
        eprintln!("{rel}: {:?}", c.report);
        let s = mesh_stats(&c.mesh, 0);
        assert_eq!(s.non_manifold_edges, 0, "{rel}");
        assert_eq!(s.non_manifold_vertices, 0, "{rel}");
        assert_eq!(s.duplicate_faces, 0, "{rel}");
        assert!(
            Topology::from_mesh(&c.mesh).is_ok() || c.report.non_orientable_components > 0,
            "{rel}"
        );
    }
}
