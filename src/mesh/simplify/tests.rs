use super::*;

/// A torus of `n x m` quads split into triangles (R = 1, r = 0.4).
pub(crate) fn torus(n: usize, m: usize) -> TriMesh {
    let mut positions = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (a, b) = (
                std::f64::consts::TAU * i as f64 / n as f64,
                std::f64::consts::TAU * j as f64 / m as f64,
            );
            let rad = 1.0 + 0.4 * b.cos();
            positions.push(DVec3::new(rad * a.cos(), rad * a.sin(), 0.4 * b.sin()));
        }
    }
    let at = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..m {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    TriMesh::new(positions, triangles)
}

/// A wavy square sheet of `k x k` cells with the middle cells cut out (one hole).
pub(super) fn holed_sheet(k: usize) -> TriMesh {
    let at = |i: usize, j: usize| (j * (k + 1) + i) as u32;
    let mut positions = Vec::new();
    for j in 0..=k {
        for i in 0..=k {
            let (x, y) = (i as f64 / k as f64, j as f64 / k as f64);
            positions.push(DVec3::new(x, y, 0.1 * (3.0 * x).sin() * (2.0 * y).cos()));
        }
    }
    let mut triangles = Vec::new();
    let hole = k / 2 - 1..k / 2 + 1;
    for j in 0..k {
        for i in 0..k {
            if hole.contains(&i) && hole.contains(&j) {
                continue;
            }
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    // The vertices inside the hole belong to no face: dropped.
    let mut used = vec![u32::MAX; positions.len()];
    for t in &triangles {
        for &v in t {
            used[v as usize] = 0;
        }
    }
    let mut kept = Vec::new();
    for (v, u) in used.iter_mut().enumerate() {
        if *u == 0 {
            *u = kept.len() as u32;
            kept.push(positions[v]);
        }
    }
    for t in &mut triangles {
        *t = t.map(|v| used[v as usize]);
    }
    TriMesh::new(kept, triangles)
}

pub(super) fn check_result(input: &TriMesh, out: &Simplified, opts: &SimplifyOptions) {
    let topo = Topology::from_mesh(&out.mesh).expect("manifold result");
    for v in 0..out.mesh.positions.len() as u32 {
        let faces = topo.face_valence[v as usize] as usize;
        if topo.is_boundary(v) {
            assert!(
                faces < opts.max_faces_per_vertex,
                "vertex {v}: {faces} faces"
            );
        } else {
            assert!(
                (3..=opts.max_faces_per_vertex).contains(&faces),
                "vertex {v}: {faces}"
            );
        }
    }
    assert_eq!(out.landing.len(), input.positions.len());
    for l in &out.landing {
        assert!((l.face as usize) < out.mesh.triangles.len());
        assert!(l.u >= 0.0 && l.v >= 0.0 && l.u + l.v <= 1.0 + 1e-12);
    }
    for (v, &c) in out.control_of.iter().enumerate() {
        if c != REMOVED {
            assert!((c as usize) < out.mesh.positions.len(), "input {v}");
        }
    }
}

#[test]
fn a_torus_keeps_genus_one_down_to_the_target() {
    let mesh = torus(40, 20);
    let opts = SimplifyOptions {
        target_vertices: 60,
        ..Default::default()
    };
    let out = simplify(&mesh, &opts).expect("simplified");
    assert_eq!(out.mesh.positions.len(), 60);
    check_result(&mesh, &out, &opts);
    let t = SurfaceTopology::of(&out.mesh).expect("manifold");
    assert_eq!(
        (t.euler, t.genus, t.boundary_loops, t.components),
        (0, 1, 0, 1)
    );
    // Control vertices stay near the torus (a quadric minimiser on a convex-concave
    // surface sits within a fraction of the edge length of it).
    for p in &out.mesh.positions {
        let ring = (DVec3::new(p.x, p.y, 0.0).length() - 1.0).hypot(p.z);
        assert!((ring - 0.4).abs() < 0.08, "{p}: {ring}");
    }
}

#[test]
fn a_hole_and_the_sheet_corners_survive() {
    let mesh = holed_sheet(24);
    let opts = SimplifyOptions {
        target_vertices: 40,
        ..Default::default()
    };
    let out = simplify(&mesh, &opts).expect("simplified");
    check_result(&mesh, &out, &opts);
    let t = SurfaceTopology::of(&out.mesh).expect("manifold");
    assert_eq!((t.boundary_loops, t.genus, t.components), (2, 0, 1));
    // The outer corners turn by 90 degrees: locked, so kept in place.
    for (x, y) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
        let corner = mesh
            .positions
            .iter()
            .position(|p| p.x == x && p.y == y)
            .expect("a sheet corner");
        let c = out.control_of[corner];
        assert_ne!(c, REMOVED, "corner {corner}");
        assert_eq!(out.mesh.positions[c as usize], mesh.positions[corner]);
    }
    // Boundary vertices stay on the sheet's rim or the hole's rim.
    let topo = Topology::from_mesh(&out.mesh).expect("manifold");
    for v in 0..out.mesh.positions.len() as u32 {
        if topo.is_boundary(v) {
            let p = out.mesh.positions[v as usize];
            // Within 1e-3, under 1 % of a final edge (the constraint planes of a rim that
            // curves in z meet slightly off it).
            let tol = 1e-3;
            let near_hole =
                (p.x - 0.5).abs() <= 1.0 / 24.0 + tol && (p.y - 0.5).abs() <= 1.0 / 24.0 + tol;
            let on_rim = p.x.abs() < tol
                || p.y.abs() < tol
                || (p.x - 1.0).abs() < tol
                || (p.y - 1.0).abs() < tol
                || near_hole;
            assert!(on_rim, "boundary control {v} at {p} left the rims");
        }
    }
}

#[test]
fn carried_points_land_near_their_own_position() {
    let mesh = torus(48, 24);
    let opts = SimplifyOptions {
        target_vertices: 200,
        ..Default::default()
    };
    let out = simplify(&mesh, &opts).expect("simplified");
    let edge = 2.0 * std::f64::consts::PI * 1.4 / 14.0;
    for (p, l) in mesh.positions.iter().zip(&out.landing) {
        let q = l
            .position_on(&out.mesh)
            .expect("a face of the simplified mesh");
        assert!((q - *p).length() < 0.25 * edge, "{p} landed at {q}");
    }
}

#[test]
fn simplification_is_deterministic() {
    let mesh = holed_sheet(20);
    let opts = SimplifyOptions {
        target_vertices: 50,
        ..Default::default()
    };
    let a = simplify(&mesh, &opts).expect("simplified");
    let b = simplify(&mesh, &opts).expect("simplified");
    assert_eq!(a.mesh, b.mesh);
    assert_eq!(a.landing, b.landing);
    // The topology built by the caller gives the same result, off the origin too (where
    // the mesh is simplified as a moved copy).
    for shift in [DVec3::ZERO, DVec3::new(5e3, -2e3, 1e3)] {
        let moved = TriMesh::new(
            mesh.positions.iter().map(|p| *p + shift).collect(),
            mesh.triangles.clone(),
        );
        let topo = Topology::from_mesh(&moved).expect("manifold");
        let plain = simplify(&moved, &opts).expect("simplified");
        let built = simplify_with_topology(&moved, &topo, &opts, &[]).expect("simplified");
        assert_eq!(plain.mesh, built.mesh);
        assert_eq!(plain.landing, built.landing);
    }
}
