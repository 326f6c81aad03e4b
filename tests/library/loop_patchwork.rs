//! Loop limit surfaces as CAD patches (`bspline::loop_patches`): exact on regular faces,
//! converging under splits elsewhere, watertight, and measured honestly (the reported
//! deviation checked against B-spline evaluation of the written patches at parameters the
//! measurement never used).

use glam::DVec3;
use std::collections::HashMap;
use trispline::bspline::loop_patches::{loop_patchwork, Patchwork, Split};
use trispline::bspline::BSplineSurface;
use trispline::surface::loop_limit::LoopLimitSurface;
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::testdata::{faceted_prism, icosahedron, uniform};

/// `testdata::regular_torus` as a control net.
fn regular_torus(n: usize, m: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let mesh = trispline::testdata::regular_torus(n, m);
    (mesh.positions, mesh.triangles)
}

/// The tensor-form parameter of face parameter (u, v) on a depth-0 patch: u = s,
/// v = (1 - s) t.
fn tensor_param(u: f64, v: f64) -> (f64, f64) {
    (u, if u < 1.0 { v / (1.0 - u) } else { 0.0 })
}

/// Largest distance from random limit points of each face to the (depth 0) patchwork: the
/// nearest of the face's own patch (searched from the point's parameter) and every other
/// patch (from its middle), by the B-spline's own closest-point search.
fn sampled_distance(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    work: &Patchwork,
    per_face: usize,
) -> f64 {
    assert_eq!(work.split, Split::default());
    let mut seed = 7u64;
    let mut worst = 0.0f64;
    for (f, patch) in work.patches.iter().enumerate() {
        for _ in 0..per_face {
            let (mut u, mut v) = (uniform(&mut seed), uniform(&mut seed));
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let limit = surface
                .evaluate(
                    controls,
                    SurfaceParam {
                        face: f as u32,
                        u,
                        v,
                    },
                )
                .position;
            let own = patch.closest_point(limit, tensor_param(u, v)).1;
            let nearest = work
                .patches
                .iter()
                .map(|other| other.closest_point(limit, (0.3, 0.5)).1)
                .fold(own, f64::min);
            worst = worst.max(nearest);
        }
    }
    worst
}

/// How many patches hold each patch edge (its five control points, either direction):
/// columns t = 0 and t = 1 and row s = 0 of the 5 x 5 grid; the row s = 1 is collapsed.
fn edge_uses(patches: &[BSplineSurface]) -> HashMap<Vec<[u64; 3]>, usize> {
    let bits = |p: DVec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    let mut uses = HashMap::new();
    for patch in patches {
        let c = patch.controls();
        for edge in [
            (0..5).map(|i| c[i * 5]).collect::<Vec<_>>(),
            (0..5).map(|i| c[i * 5 + 4]).collect(),
            (0..5).map(|j| c[j]).collect(),
        ] {
            let mut key: Vec<[u64; 3]> = edge.iter().map(|&p| bits(p)).collect();
            let reversed: Vec<[u64; 3]> = key.iter().rev().copied().collect();
            if reversed < key {
                key = reversed;
            }
            *uses.entry(key).or_insert(0) += 1;
        }
        assert!(
            (1..5).all(|j| c[20 + j] == c[20]),
            "the side s = 1 collapses to one corner"
        );
    }
    uses
}

#[test]
fn regular_faces_are_written_exactly() {
    let (controls, faces) = regular_torus(12, 8);
    let surface = LoopLimitSurface::new(controls.len(), &faces).expect("manifold");
    let work = loop_patchwork(&surface, &controls, Split::default()).expect("patchwork");
    assert_eq!(work.patches.len(), faces.len());
    assert_eq!(work.exact_faces, faces.len());
    assert!(work.deviation.max < 1e-12, "{:?}", work.deviation);
    let sampled = sampled_distance(&surface, &controls, &work, 20);
    assert!(sampled < 1e-12, "B-spline evaluation off by {sampled:e}");
    // A closed surface: every patch edge is held by two patches.
    assert!(edge_uses(&work.patches).values().all(|&n| n == 2));
}

#[test]
fn extraordinary_vertices_converge_under_splits_and_stay_watertight() {
    let (controls, faces) = icosahedron();
    let surface = LoopLimitSurface::new(controls.len(), &faces).expect("manifold");
    let deviations: Vec<f64> = (0..3)
        .map(|depth| {
            let split = Split {
                depth,
                corner_levels: 0,
            };
            let work = loop_patchwork(&surface, &controls, split).expect("patchwork");
            assert_eq!(work.patches.len(), faces.len() << (2 * depth));
            assert_eq!(work.exact_faces, 0);
            let uses = edge_uses(&work.patches);
            assert_eq!(uses.len(), 30 << (2 * depth), "edges of the split");
            assert!(
                uses.values().all(|&n| n == 2),
                "watertight at depth {depth}"
            );
            if depth == 0 {
                // The reported maximum is measured on a lattice; points off it agree.
                let sampled = sampled_distance(&surface, &controls, &work, 200);
                assert!(
                    sampled <= 1.5 * work.deviation.max,
                    "{sampled:e} against {:e}",
                    work.deviation.max
                );
            }
            work.deviation.max
        })
        .collect();
    // The icosahedron's limit surface is about 3.3 across.
    assert!(deviations[0] < 1e-2, "{deviations:?}");
    assert!(
        deviations[1] < 0.7 * deviations[0] && deviations[2] < 0.7 * deviations[1],
        "{deviations:?}"
    );
}

#[test]
fn crease_edges_and_boundaries_stay_shared_edges() {
    // A prism with sharp rims, opened at one end: crease vertices, corners and a boundary.
    let (mesh, creases) = faceted_prism(6, 3, 2);
    let top = mesh.positions.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let mut faces = mesh.triangles.clone();
    faces.retain(|t| {
        !t.iter()
            .all(|&v| mesh.positions[v as usize].z >= top - 1e-9)
    });
    let creases: Vec<[u32; 2]> = creases
        .into_iter()
        .filter(|e| e.iter().all(|&v| faces.iter().any(|t| t.contains(&v))))
        .collect();
    // Without the cap its centre is unused: number the vertices left.
    let mut index = vec![u32::MAX; mesh.positions.len()];
    let mut controls = Vec::new();
    for t in faces.iter_mut() {
        for v in t.iter_mut() {
            if index[*v as usize] == u32::MAX {
                index[*v as usize] = controls.len() as u32;
                controls.push(mesh.positions[*v as usize]);
            }
            *v = index[*v as usize];
        }
    }
    let creases: Vec<[u32; 2]> = creases
        .iter()
        .map(|e| e.map(|v| index[v as usize]))
        .collect();
    let surface =
        LoopLimitSurface::with_creases(controls.len(), &faces, &creases).expect("manifold");
    let split = Split {
        depth: 1,
        corner_levels: 0,
    };
    let work = loop_patchwork(&surface, &controls, split).expect("patchwork");
    let uses = edge_uses(&work.patches);
    let mut edge_faces: HashMap<(u32, u32), usize> = HashMap::new();
    for t in &faces {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edge_faces.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let boundary = edge_faces.values().filter(|&&n| n == 1).count();
    assert!(boundary > 0);
    // Each boundary control edge is two patch edges at depth 1, held once; all others twice.
    assert_eq!(uses.values().filter(|&&n| n == 1).count(), 2 * boundary);
    assert!(uses.values().all(|&n| n == 1 || n == 2));
    let size = controls.iter().map(|p| p.length()).fold(0.0, f64::max);
    assert!(work.deviation.max < 1e-2 * size, "{:?}", work.deviation);
}

#[test]
fn a_control_count_that_does_not_match_is_refused() {
    let (controls, faces) = icosahedron();
    let surface = LoopLimitSurface::new(controls.len(), &faces).expect("manifold");
    assert!(loop_patchwork(&surface, &controls[..11], Split::default()).is_err());
}

#[test]
fn splits_at_irregular_vertices_conform_and_shrink_the_largest_deviation() {
    // The icosahedron's vertices are all extraordinary: level 1 cuts each face in four,
    // every later level cuts each of the three corner triangles in three.
    let (controls, faces) = icosahedron();
    let surface = LoopLimitSurface::new(controls.len(), &faces).expect("manifold");
    let mut last = f64::INFINITY;
    for corner_levels in 0..4 {
        let split = Split {
            depth: 0,
            corner_levels,
        };
        let work = loop_patchwork(&surface, &controls, split).expect("patchwork");
        let per_face = match corner_levels {
            0 => 1,
            l => 4 + 6 * (l as usize - 1),
        };
        assert_eq!(work.patches.len(), 20 * per_face);
        assert!(
            edge_uses(&work.patches).values().all(|&n| n == 2),
            "watertight at {corner_levels} levels"
        );
        assert!(
            work.deviation.max < 0.7 * last,
            "{corner_levels}: {:?} after {last:e}",
            work.deviation
        );
        last = work.deviation.max;
    }
    // A regular mesh has no irregular vertex: corner levels change nothing.
    let (controls, faces) = regular_torus(12, 8);
    let surface = LoopLimitSurface::new(controls.len(), &faces).expect("manifold");
    let split = Split {
        depth: 0,
        corner_levels: 3,
    };
    let work = loop_patchwork(&surface, &controls, split).expect("patchwork");
    assert_eq!(work.patches.len(), faces.len());
}
