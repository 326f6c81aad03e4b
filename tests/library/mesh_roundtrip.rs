//! Inverse Loop undoes forward Loop exactly, on generated meshes covering closed and open
//! surfaces, valences 3 to 12, corners and several components.

use glam::DVec3;
use trispline::mesh::detect::Hierarchy;
use trispline::mesh::inverse::{coarsen, InverseMethod};
use trispline::mesh::loop_subdiv::subdivide;
use trispline::mesh::topology::Topology;
use trispline::TriMesh;

fn jitter(i: usize) -> DVec3 {
    // Deterministic pseudo-random offsets so that no symmetry hides an error.
    let h = |k: u64| {
        let mut x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ k;
        x ^= x >> 31;
        x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x ^= x >> 29;
        (x % 10_000) as f64 / 10_000.0 - 0.5
    };
    DVec3::new(h(1), h(2), h(3)) * 0.1
}

fn tetrahedron() -> TriMesh {
    TriMesh::new(
        vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
        vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    )
}

/// An octahedron, outward oriented: +x, -x, +y, -y, +z, -z.
pub(crate) fn octahedron() -> TriMesh {
    let (p, t) = trispline::testdata::octahedron();
    TriMesh::new(p, t)
}

/// A double cone around an n-ring: two apices of valence n, ring vertices of valence 4.
fn bipyramid(n: usize) -> TriMesh {
    let mut p: Vec<DVec3> = (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            DVec3::new(a.cos(), a.sin(), 0.0)
        })
        .collect();
    p.push(DVec3::Z);
    p.push(-DVec3::Z);
    let (top, bottom) = (n as u32, n as u32 + 1);
    let mut t = Vec::new();
    for k in 0..n as u32 {
        let k1 = (k + 1) % n as u32;
        t.push([k, k1, top]);
        t.push([k1, k, bottom]);
    }
    TriMesh::new(p, t)
}

/// An open triangulated grid: two corners with a single face, boundary valences 2..4.
fn grid(n: usize) -> TriMesh {
    let mut p = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            p.push(DVec3::new(i as f64, j as f64, ((i * j) as f64 * 0.3).sin()));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut t = Vec::new();
    for j in 0..n {
        for i in 0..n {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(p, t)
}

fn merged(parts: &[TriMesh]) -> TriMesh {
    let mut m = TriMesh::default();
    for (k, part) in parts.iter().enumerate() {
        let off = m.positions.len() as u32;
        m.positions.extend(
            part.positions
                .iter()
                .map(|p| *p + DVec3::X * 5.0 * k as f64),
        );
        m.triangles.extend(
            part.triangles
                .iter()
                .map(|t| [t[0] + off, t[1] + off, t[2] + off]),
        );
    }
    m
}

fn jittered(mut m: TriMesh) -> TriMesh {
    for (i, p) in m.positions.iter_mut().enumerate() {
        *p += jitter(i);
    }
    m
}

fn cases() -> Vec<(&'static str, TriMesh)> {
    vec![
        ("tetrahedron (valence 3)", jittered(tetrahedron())),
        ("octahedron (valence 4)", jittered(octahedron())),
        ("bipyramid-5", jittered(bipyramid(5))),
        ("bipyramid-12 (valence 12)", jittered(bipyramid(12))),
        ("open grid with corners", jittered(grid(3))),
        (
            "single triangle (three corners)",
            jittered(TriMesh::new(
                vec![DVec3::ZERO, DVec3::X, DVec3::Y],
                vec![[0, 1, 2]],
            )),
        ),
        (
            "three components",
            jittered(merged(&[tetrahedron(), grid(2), bipyramid(7)])),
        ),
    ]
}

fn max_rel_diff(a: &[DVec3], b: &[DVec3]) -> f64 {
    let scale = a.iter().map(|p| p.length()).fold(1e-300, f64::max);
    a.iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f64::max)
        / scale
}

#[test]
fn coarsen_undoes_subdivide_for_one_to_three_levels_with_both_methods() {
    for (name, mesh) in cases() {
        for levels in 1..=3 {
            let fine = subdivide(&mesh, levels).expect("generated meshes are manifold");
            assert_eq!(
                &fine.positions[..mesh.positions.len()],
                &fine.positions[..mesh.positions.len()]
            );
            for method in [InverseMethod::Exact, InverseMethod::Lsq] {
                let c = coarsen(&fine, levels, method)
                    .unwrap_or_else(|e| panic!("{name} L={levels}: {e}"));
                assert_eq!(
                    c.mesh.positions.len(),
                    mesh.positions.len(),
                    "{name} L={levels}"
                );
                let err = max_rel_diff(&mesh.positions, &c.mesh.positions);
                assert!(
                    err < 1e-12,
                    "{name} L={levels} {method:?}: relative error {err:e}"
                );
                let mut want: Vec<[u32; 3]> =
                    mesh.triangles.iter().map(|t| canonical(*t)).collect();
                let mut got: Vec<[u32; 3]> =
                    c.mesh.triangles.iter().map(|t| canonical(*t)).collect();
                want.sort_unstable();
                got.sort_unstable();
                assert_eq!(want, got, "{name} L={levels}: coarse connectivity differs");
            }
        }
    }
}

/// Rotates a triangle so its smallest index comes first, keeping orientation.
fn canonical(t: [u32; 3]) -> [u32; 3] {
    let k = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

#[test]
fn detection_depth_matches_the_levels_applied() {
    for (name, mesh) in cases() {
        let fine = subdivide(&mesh, 3).expect("manifold");
        let topo = Topology::from_mesh(&fine).expect("manifold");
        let (h, _) = Hierarchy::detect(&topo, 3);
        assert_eq!(h.depth(), 3, "{name}");
        // Every fine vertex gets a location whose barycentric weights are dyadic and valid.
        for (f, u, v) in h.fine_vertex_params(&topo) {
            assert!((f as usize) < mesh.triangles.len(), "{name}");
            assert!(u >= 0.0 && v >= 0.0 && u + v <= 1.0 + 1e-15, "{name}");
            assert_eq!((u * 8.0).fract(), 0.0, "{name}: u={u} not dyadic");
        }
    }
}

#[test]
fn coarsest_vertices_keep_their_index_and_sit_at_a_corner_of_their_face() {
    let mesh = jittered(bipyramid(7));
    let fine = subdivide(&mesh, 2).expect("manifold");
    let topo = Topology::from_mesh(&fine).expect("manifold");
    let (h, _) = Hierarchy::detect(&topo, 2);
    let params = h.fine_vertex_params(&topo);
    let to_fine = h.coarsest_to_fine();
    // Even vertices of the coarsest level keep their index and sit at a corner.
    for (c, &f) in to_fine.iter().enumerate() {
        assert_eq!(c as u32, f);
        let (face, u, v) = params[f as usize];
        let coarse = &h.levels.last().expect("two levels").coarse_triangles;
        let t = coarse[face as usize];
        let w = 1.0 - u - v;
        let corner = [u, v, w]
            .iter()
            .position(|&x| x == 1.0)
            .expect("at a corner");
        assert_eq!(t[corner], c as u32);
    }
}

#[test]
fn a_flipped_edge_breaks_detection_with_a_reason() {
    let fine = subdivide(&jittered(octahedron()), 1).expect("manifold");
    let topo = Topology::from_mesh(&fine).expect("manifold");
    // Flip the shared edge of faces 0 and its neighbour across half-edge 0.
    let h = 0u32;
    let t = topo.twin[h as usize];
    let (f, g) = ((h / 3) as usize, (t / 3) as usize);
    let a = fine.triangles[f][0];
    let b = fine.triangles[f][1];
    let c = topo.opposite(h);
    let d = topo.opposite(t);
    let mut tris = fine.triangles.clone();
    tris[f] = [c, a, d];
    tris[g] = [d, b, c];
    let broken = TriMesh::new(fine.positions.clone(), tris);
    let err = coarsen(&broken, 1, InverseMethod::Exact)
        .err()
        .expect("must fail");
    let msg = err.to_string();
    assert!(msg.contains("level 1") && msg.contains("vertex"), "{msg}");
}

#[test]
fn lsq_amplifies_noise_less_than_exact() {
    let smooth = subdivide(&bipyramid(6), 1).expect("manifold");
    let fine = subdivide(&smooth, 1).expect("manifold");
    let mut noisy = fine.clone();
    for (i, p) in noisy.positions.iter_mut().enumerate() {
        *p += jitter(i + 1000) * 0.01;
    }
    let exact = coarsen(&noisy, 1, InverseMethod::Exact).expect("subdivided");
    let lsq = coarsen(&noisy, 1, InverseMethod::Lsq).expect("subdivided");
    let rms = |c: &TriMesh| {
        (c.positions
            .iter()
            .zip(&smooth.positions)
            .map(|(a, b)| (*a - *b).length_squared())
            .sum::<f64>()
            / c.positions.len() as f64)
            .sqrt()
    };
    let (e, l) = (rms(&exact.mesh), rms(&lsq.mesh));
    eprintln!("noise test: rms error of coarse net, exact {e:.3e}, lsq {l:.3e}");
    assert!(l < e, "lsq {l} should beat exact {e}");
}
