//! The Loop limit surface near extraordinary vertices and across faces: non-dyadic
//! parameters against deep subdivision, steps across edges, mixed valences, boundary normals
//! and the cached evaluator. Meshes and helpers come from `loop_limit`.

use super::loop_limit::*;
use glam::DVec3;
use trispline::mesh::topology::{Topology, NONE};
use trispline::surface::loop_limit::{LoopLimitError, LoopLimitSurface};
use trispline::surface::{SurfaceParam, TriSurface};

#[test]
fn non_dyadic_parameters_near_extraordinary_vertices_match_deep_subdivision() {
    // Interpolating the limit positions of the fine face around p converges at second
    // order in the fine edge length, to the surface value.
    let mut r = Rng(29);
    for m in [polar(7, 2, true, 8), polar(3, 2, true, 9)] {
        let s = surface(&m);
        let sc = scale(&m);
        let params: Vec<(usize, f64, f64)> = (0..12)
            .map(|i| {
                // The centre is corner 0 of the first face of every sector.
                let f = (i % (m.tris.len() / 4)) * 4;
                let d = r.range(0.01, 0.2);
                (f, 1.0 - d, r.range(0.0, 0.9) * d)
            })
            .collect();
        let mut errs = Vec::new();
        for level in [4usize, 6] {
            let fine = subdivide(&m, level);
            let topo = Topology::build(fine.pos.len(), &fine.tris).expect("manifold");
            let lim = limit_positions(&topo, &fine.pos);
            let mut err = 0.0f64;
            for &(f, u, v) in &params {
                let e = eval(&s, &m, f, u, v);
                let (t, b) = fine
                    .tris
                    .iter()
                    .zip(&fine.origin)
                    .find_map(|(t, &(c, b))| {
                        if c != f {
                            return None;
                        }
                        // Barycentric coordinates of p in the fine face.
                        let m3 = nalgebra::Matrix3::new(
                            b[0][0], b[1][0], b[2][0], b[0][1], b[1][1], b[2][1], 1.0, 1.0, 1.0,
                        );
                        let x = m3.try_inverse()? * nalgebra::Vector3::new(u, v, 1.0);
                        (x.iter().all(|&c| c > -1e-12)).then_some((t, x))
                    })
                    .expect("the fine faces tile the coarse face");
                let interp = lim[t[0] as usize] * b[0]
                    + lim[t[1] as usize] * b[1]
                    + lim[t[2] as usize] * b[2];
                err = err.max((interp - e.position).length() / sc);
            }
            errs.push(err);
        }
        assert!(errs[1] < 2e-3, "{}: {errs:?}", m.name);
        assert!(
            errs[1] < errs[0] / 4.0,
            "{}: not converging {errs:?}",
            m.name
        );
        println!(
            "{}: |S(p) - fine interpolant|, levels 4 and 6: {:e} {:e}",
            m.name, errs[0], errs[1]
        );
    }
}

#[test]
fn step_crosses_faces_where_the_unfolded_lattice_says() {
    // A planar lattice: the parameter plane unfolds isometrically onto the mesh plane.
    let m = lattice(10, 1);
    let s = surface(&m);
    let planar = |p: SurfaceParam| {
        let t = m.tris[p.face as usize];
        let q = |k: usize| m.pos[t[k] as usize].truncate();
        q(0) * p.u + q(1) * p.v + q(2) * (1.0 - p.u - p.v)
    };
    let centre = glam::DVec2::new(5.0, 10.0 * 3f64.sqrt() / 6.0);
    let mut r = Rng(3);
    let mut crossings = 0;
    let mut worst = 0.0f64;
    for f in 0..m.tris.len() {
        let t = m.tris[f];
        let g = |k: usize| m.pos[t[k] as usize].truncate();
        let mid = (g(0) + g(1) + g(2)) / 3.0;
        // Faces near the centre of the 10-lattice triangle (inradius 2.9), steps up to 1.2
        // edge lengths.
        if (mid - centre).length() > 0.9 {
            continue;
        }
        for _ in 0..10 {
            let u = r.f();
            let v = r.f() * (1.0 - u);
            let p = SurfaceParam {
                face: f as u32,
                u,
                v,
            };
            let (du, dv) = (r.range(-0.6, 0.6), r.range(-0.6, 0.6));
            let q = s.step(p, du, dv);
            let want = planar(p) + (g(0) - g(2)) * du + (g(1) - g(2)) * dv;
            let err = (planar(q) - want).length();
            assert!(
                err < 1e-12,
                "face {f} {p:?} + ({du}, {dv}) -> {q:?}: {err:e}"
            );
            worst = worst.max(err);
            crossings += usize::from(q.face != p.face);
        }
    }
    assert!(crossings > 20, "{crossings}");
    // Far outside: clamped onto the boundary, a valid parameter.
    let q = s.step(
        SurfaceParam {
            face: 0,
            u: 0.3,
            v: 0.3,
        },
        -50.0,
        -20.0,
    );
    let w = 1.0 - q.u - q.v;
    assert!(q.u >= 0.0 && q.v >= 0.0 && w >= -1e-15);
    let t = m.tris[q.face as usize];
    let topo = Topology::build(m.pos.len(), &m.tris).expect("manifold");
    let on_boundary_edge = (0..3).any(|k| {
        let b = [q.u, q.v, w];
        b[(k + 2) % 3].abs() < 1e-12 && topo.twin[3 * q.face as usize + k] == NONE
    });
    assert!(on_boundary_edge, "{q:?} {t:?}");
    println!("step: {crossings} crossings, max deviation from the unfolded lattice {worst:e}");
}

#[test]
fn extraordinary_vertices_give_finite_rows_and_a_tangent_plane() {
    for m in [
        polar(3, 2, true, 1),
        polar(5, 2, true, 2),
        polar(8, 2, true, 3),
        polar(2, 3, false, 4),
        polar(5, 3, false, 5),
        polar(1, 3, false, 6),
    ] {
        let s = surface(&m);
        // Corner 0 of face 0 is the centre.
        let e = eval(&s, &m, 0, 1.0, 0.0);
        let n = e.du.cross(e.dv);
        assert!(n.length() > 1e-12, "{}: {e:?}", m.name);
        let near = eval(&s, &m, 0, 1.0 - 2e-7, 1e-7);
        let nn = near.du.cross(near.dv);
        let angle = n.angle_between(nn);
        assert!(angle < 0.05, "{}: normal off by {angle}", m.name);
        println!(
            "{}: normal at the vertex vs 1e-7 away: {angle:e} rad",
            m.name
        );
    }
}

#[test]
fn refuses_bad_meshes() {
    assert!(matches!(
        LoopLimitSurface::new(3, &[[0, 1, 3]]),
        Err(LoopLimitError::IndexOutOfRange { .. })
    ));
    assert!(matches!(
        LoopLimitSurface::new(4, &[[0, 1, 2]]),
        Err(LoopLimitError::IsolatedVertex { vertex: 3 })
    ));
    assert!(matches!(
        LoopLimitSurface::new(5, &[[0, 1, 2], [0, 1, 3], [0, 1, 4]]),
        Err(LoopLimitError::NonManifold(_))
    ));
    assert!(matches!(
        LoopLimitSurface::new(3, &[[0, 1, 1]]),
        Err(LoopLimitError::DegenerateFace { .. })
    ));
    fn sync<T: Sync + Send>() {}
    sync::<LoopLimitSurface>();
}

#[test]
fn small_steps_across_edges_follow_the_derivatives_on_irregular_meshes() {
    // A step across an edge moves the surface point by the first-order change the
    // derivatives predict: the unfolding agrees with the C1 structure of the surface.
    let mut r = Rng(41);
    let mut worst = 0.0f64;
    for m in [polar(5, 2, true, 1), polar(8, 2, true, 2), icosahedron()] {
        let s = surface(&m);
        let sc = scale(&m);
        let mut crossed = 0;
        for f in 0..m.tris.len() {
            for _ in 0..6 {
                // Start 0.02 from an edge and step 0.04 across it.
                let t = r.range(0.1, 0.88);
                let (u, v, du, dv) = match r.f() {
                    x if x < 1.0 / 3.0 => (0.02, t, -0.04, 0.0),
                    x if x < 2.0 / 3.0 => (t, 0.02, 0.0, -0.04),
                    _ => (t, 0.98 - t, 0.02, 0.02),
                };
                let p = SurfaceParam {
                    face: f as u32,
                    u,
                    v,
                };
                let e = s.evaluate(&m.pos, p);
                let q = s.step(p, du, dv);
                if q.face == p.face {
                    // Clamped at the mesh boundary.
                    assert!(q.u.min(q.v).min(1.0 - q.u - q.v) < 1e-15, "{q:?}");
                    continue;
                }
                crossed += 1;
                // Second-order residual: half the Hessian along the step, taken at p.
                let lin = e.position + e.du * du + e.dv * dv;
                let quad = lin + (e.duu * du * du + e.duv * 2.0 * du * dv + e.dvv * dv * dv) * 0.5;
                let got = s.evaluate(&m.pos, q).position;
                let err = (got - quad).length() / sc;
                let step_len = du.abs() + dv.abs();
                assert!(
                    err < 2.0 * step_len.powi(3) + 1e-12,
                    "{} face {f} {p:?} + ({du}, {dv}) -> {q:?}: {err:e}",
                    m.name
                );
                worst = worst.max(err / step_len.powi(3));
            }
        }
        assert!(crossed > 2 * m.tris.len(), "{}: {crossed}", m.name);
    }
    println!("steps across edges: max |S(step) - quadratic Taylor| / |d|^3 = {worst:e}");
}

#[test]
fn ghost_point_box_splines_are_exact_on_regular_boundary_faces() {
    // Regular faces touching the boundary are evaluated as box splines with ghost points
    // v + a - b, without subdivision: the hypothesis that this is exact, checked on those
    // faces alone against the dyadic limit masks.
    let mut worst = 0.0f64;
    let mut faces = 0;
    for m in [
        lattice(6, 51),
        polar(6, 4, true, 52),
        polar(3, 4, false, 53),
    ] {
        let s = surface(&m);
        let sc = scale(&m);
        let topo = Topology::build(m.pos.len(), &m.tris).expect("manifold");
        let ghost: Vec<bool> = (0..m.tris.len())
            .map(|f| s.is_regular_face(f) && m.tris[f].iter().any(|&v| topo.is_boundary(v)))
            .collect();
        faces += ghost.iter().filter(|&&g| g).count();
        for level in 1..=4 {
            let f = subdivide(&m, level);
            let ft = Topology::build(f.pos.len(), &f.tris).expect("manifold");
            let lim = limit_positions(&ft, &f.pos);
            for (t, &(c, bary)) in f.tris.iter().zip(&f.origin) {
                if !ghost[c] {
                    continue;
                }
                for k in 0..3 {
                    let e = eval(&s, &m, c, bary[k][0], bary[k][1]);
                    let err = (e.position - lim[t[k] as usize]).length() / sc;
                    assert!(err < 1e-12, "{} face {c} level {level}: {err:e}", m.name);
                    worst = worst.max(err);
                }
            }
        }
    }
    assert!(faces > 30, "{faces}");
    println!("ghost-point boundary patches: {faces} faces, max relative deviation {worst:e}");
}

/// Random edge flips on a closed mesh: neighbouring extraordinary vertices of mixed
/// valences, faces with two or three of them.
fn flipped(m: Mesh, flips: usize, seed: u64) -> Mesh {
    let mut tris = m.tris.clone();
    let mut r = Rng(seed);
    let mut done = 0;
    for _ in 0..flips * 20 {
        if done == flips {
            break;
        }
        let topo = Topology::build(m.pos.len(), &tris).expect("manifold");
        let h = (r.f() * topo.twin.len() as f64) as usize % topo.twin.len();
        let t = topo.twin[h];
        if t == NONE {
            continue;
        }
        let (f, g) = (h / 3, t as usize / 3);
        let (a, b) = (tris[f][h % 3], tris[f][(h % 3 + 1) % 3]);
        let (c, d) = (topo.opposite(h as u32), topo.opposite(t));
        if c == d || topo.valence(a) <= 4 || topo.valence(b) <= 4 || topo.ring(c).contains(&d) {
            continue;
        }
        // Triangles (a, b, c) and (b, a, d) become (c, a, d) and (d, b, c): same orientation.
        tris[f] = [c, a, d];
        tris[g] = [d, b, c];
        if Topology::build(m.pos.len(), &tris).is_err() {
            return Mesh { tris: m.tris, ..m };
        }
        done += 1;
    }
    Mesh {
        name: format!("{} with {done} flips", m.name),
        pos: m.pos,
        tris,
    }
}

#[test]
fn mixed_valence_neighbourhoods_match_dyadic_masks_and_are_c1() {
    let base = {
        let ico = icosahedron();
        let f = subdivide(&ico, 1);
        let mut pos = f.pos;
        bump(&mut pos, 61);
        Mesh {
            name: "icosahedron level 1".into(),
            pos,
            tris: f.tris,
        }
    };
    let m = flipped(base, 25, 62);
    let s = surface(&m);
    let sc = scale(&m);
    let topo = Topology::build(m.pos.len(), &m.tris).expect("manifold");
    let valences: std::collections::BTreeSet<usize> =
        (0..m.pos.len() as u32).map(|v| topo.valence(v)).collect();
    assert!(valences.len() >= 4, "{valences:?}");
    let mut worst = 0.0f64;
    for level in 1..=3 {
        let f = subdivide(&m, level);
        let ft = Topology::build(f.pos.len(), &f.tris).expect("manifold");
        let lim = limit_positions(&ft, &f.pos);
        for (t, &(c, bary)) in f.tris.iter().zip(&f.origin) {
            for k in 0..3 {
                let e = eval(&s, &m, c, bary[k][0], bary[k][1]);
                worst = worst.max((e.position - lim[t[k] as usize]).length() / sc);
            }
        }
    }
    assert!(worst < 1e-12, "{}: {worst:e}", m.name);
    // C1 across every edge at a random point.
    let mut r = Rng(63);
    let mut dworst = 0.0f64;
    for h in 0..topo.twin.len() {
        let tw = topo.twin[h];
        if tw < h as u32 {
            continue;
        }
        let (f, j) = (h / 3, h % 3);
        let (k, i) = ((j + 1) % 3, (j + 2) % 3);
        let (g, gk) = ((tw / 3) as usize, (tw % 3) as usize);
        let (gj, go) = ((gk + 1) % 3, (gk + 2) % 3);
        let t = r.range(0.05, 0.95);
        let (mut bf, mut bg) = ([0.0; 3], [0.0; 3]);
        (bf[j], bf[k], bg[gj], bg[gk]) = (1.0 - t, t, 1.0 - t, t);
        let ef = eval(&s, &m, f, bf[0], bf[1]);
        let eg = eval(&s, &m, g, bg[0], bg[1]);
        let across = (dir(&ef, sub(unit(i), unit(j))) - dir(&eg, sub(unit(gk), unit(go))))
            .length()
            .max((ef.position - eg.position).length());
        dworst = dworst.max(across / sc);
    }
    assert!(dworst < 1e-9, "{dworst:e}");
    println!(
        "{} (valences {valences:?}): dyadic masks {worst:e}, C1 gap {dworst:e}",
        m.name
    );
}

#[test]
fn parameters_a_hair_from_an_extraordinary_vertex_stay_finite_and_converge() {
    for m in [
        polar(3, 2, true, 71),
        polar(16, 2, true, 72),
        polar(5, 3, false, 73),
    ] {
        let s = surface(&m);
        let sc = scale(&m);
        let at = eval(&s, &m, 0, 1.0, 0.0);
        let mut last = f64::MAX;
        for e in [1e-3, 1e-6, 1e-9, 1e-12, 1e-15] {
            let d = eval(&s, &m, 0, 1.0 - e, 0.5 * e);
            for x in [d.position, d.du, d.dv, d.duu, d.duv, d.dvv] {
                assert!(x.is_finite(), "{} at {e}: {d:?}", m.name);
            }
            let gap = (d.position - at.position).length() / sc;
            assert!(
                gap <= last * 1.01 + 1e-15,
                "{} at {e}: {gap:e} after {last:e}",
                m.name
            );
            last = gap;
        }
        assert!(last < 1e-6, "{}: {last:e}", m.name);
    }
}

#[test]
fn normals_from_two_sides_converge_at_boundary_vertices_with_many_faces() {
    // Loop's standard boundary rules give a tangent plane at a boundary vertex with k
    // faces only in the limit, approached slowly for large k: the normals from the first
    // and the last face of the fan, along matching rays, must still come together.
    for m in [2usize, 4, 5, 7] {
        let mesh = polar(m, 3, false, 80 + m as u64);
        let s = surface(&mesh);
        // The centre is corner 0 of the first face of every sector.
        let centre = mesh.tris[0][0];
        let last = mesh
            .tris
            .iter()
            .rposition(|t| t[0] == centre)
            .expect("the centre has faces");
        let mut line = format!("boundary vertex with {m} faces, normal gap at");
        let mut prev = f64::MAX;
        for e in [1e-2, 1e-4, 1e-6, 1e-8, 1e-10] {
            let a = eval(&s, &mesh, 0, 1.0 - e, 0.5 * e);
            let b = eval(&s, &mesh, last, 1.0 - e, 0.5 * e);
            let gap = a.du.cross(a.dv).angle_between(b.du.cross(b.dv));
            assert!(gap <= prev + 1e-12, "{m} faces at {e}: {gap} after {prev}");
            prev = gap;
            line += &format!(" {e:e}: {gap:.1e}");
        }
        assert!(prev < 0.02, "{m} faces: {prev}");
        println!("{line} rad");
    }
}

/// The per-control-set evaluator (ordinates of regular faces, memoised descent on the
/// others) and the value-only basis row agree with the full basis rows, near and at
/// irregular vertices too.
#[test]
fn cached_evaluator_and_value_rows_equal_the_basis_rows() {
    let mut worst = 0.0f64;
    for m in meshes_with_extraordinary_vertices() {
        let s = surface(&m);
        let sc = scale(&m);
        let evaluate = s.evaluator(&m.pos);
        let mut rng = Rng(77);
        let mut row = Vec::new();
        for face in 0..m.tris.len() {
            let mut params: Vec<(f64, f64)> = vec![
                (1.0, 0.0),
                (0.0, 1.0),
                (0.0, 0.0),
                (0.5, 0.5),
                (0.0, 0.3),
                (1e-9, 1e-9),
                (1.0 - 1e-9, 0.0),
                (1e-13, 1.0 - 2e-13),
            ];
            for _ in 0..20 {
                let (u, v) = (rng.f(), rng.f());
                params.push(if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                });
            }
            for (u, v) in params {
                let p = SurfaceParam {
                    face: face as u32,
                    u,
                    v,
                };
                let want = s.evaluate(&m.pos, p);
                let got = evaluate(p);
                // Within 1e-9 of an irregular vertex the derivatives are 2^30 (second:
                // 4^30) times the differences they come from: both routes round there,
                // second derivatives to noise (eps 4^30 2^-30 ~ 1e-7 of the size).
                let w = 1.0 - u - v;
                let near = u.min(v).min(w) < 1e-6 && (u.max(v).max(w) > 1.0 - 1e-6);
                let tol_of = |k: usize| match (k, near) {
                    (0, _) => 1e-12,
                    (1 | 2, false) => 1e-11,
                    (_, false) => 1e-10,
                    (1 | 2, true) => 1e-8,
                    (_, true) => 1e-5,
                };
                for (k, (g, w)) in [
                    (got.position, want.position),
                    (got.du, want.du),
                    (got.dv, want.dv),
                    (got.duu, want.duu),
                    (got.duv, want.duv),
                    (got.dvv, want.dvv),
                ]
                .into_iter()
                .enumerate()
                {
                    let err = (g - w).length() / w.length().max(sc);
                    assert!(
                        err < tol_of(k),
                        "{} face {face} at ({u}, {v}) column {k}: {g} vs {w}",
                        m.name
                    );
                    worst = worst.max(err);
                }
                s.basis_row(p, &mut row);
                let from_row: DVec3 = row.iter().map(|&(i, w)| m.pos[i as usize] * w).sum();
                let sum: f64 = row.iter().map(|e| e.1).sum();
                assert!((sum - 1.0).abs() < 1e-14, "{}: row sums to {sum}", m.name);
                let err = (from_row - want.position).length() / sc;
                assert!(
                    err < 1e-12,
                    "{} face {face} at ({u}, {v}): value row off by {err:e}",
                    m.name
                );
            }
        }
    }
    println!("cached evaluator: max relative deviation {worst:e}");
}

/// Evaluators of two control sets used in turn on the same faces (as the stray repair
/// compares a refit with the surface before it) each give their own surface: the leaf
/// memo every thread keeps is told apart by evaluator, not only by leaf and face.
#[test]
fn interleaved_evaluators_keep_to_their_own_controls() {
    for m in meshes_with_extraordinary_vertices() {
        let s = surface(&m);
        let sc = scale(&m);
        let moved: Vec<DVec3> = m
            .pos
            .iter()
            .enumerate()
            .map(|(i, p)| *p + DVec3::new(0.1, -0.05, 0.2) * sc * (i % 3) as f64)
            .collect();
        let (first, second) = (s.evaluator(&m.pos), s.evaluator(&moved));
        let mut rng = Rng(5);
        for face in 0..m.tris.len() {
            for _ in 0..12 {
                let (u, v) = (rng.f(), rng.f());
                let (u, v) = if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                };
                let p = SurfaceParam {
                    face: face as u32,
                    u: 0.02 + 0.96 * u,
                    v: 0.01 + 0.96 * v,
                };
                for (evaluate, controls) in [(&first, &m.pos), (&second, &moved), (&first, &m.pos)]
                {
                    let (got, want) = (evaluate(p), s.evaluate(controls, p));
                    let err = (got.position - want.position).length() / sc;
                    let err_du = (got.du - want.du).length() / want.du.length().max(sc);
                    assert!(
                        err < 1e-12 && err_du < 1e-11,
                        "{} face {face} at ({}, {}): {err:e} / {err_du:e}",
                        m.name,
                        p.u,
                        p.v
                    );
                }
            }
        }
    }
}

/// At a boundary vertex whose derivatives take a deep descent, the rows are found once
/// per 1-ring shape and kept with its quadtree: a surface that takes the trees over
/// (`with_creases_reusing`, as every refinement round does) gives the same rows bit for
/// bit, and a parameter a hair from the vertex (closer than a descent would resolve) gives
/// the vertex's own position and tangent plane, where one farther in is already apart.
#[test]
fn boundary_vertex_rows_are_kept_with_the_tree_and_a_hair_from_it_are_its_own() {
    for faces in [2usize, 4, 5] {
        let m = polar(faces, 3, false, 90 + faces as u64);
        let first = surface(&m);
        let at = eval(&first, &m, 0, 1.0, 0.0);
        let reused = LoopLimitSurface::with_creases_reusing(m.pos.len(), &m.tris, &[], &first)
            .expect("the same mesh");
        let again = eval(&reused, &m, 0, 1.0, 0.0);
        assert_eq!(
            [at.position, at.du, at.dv],
            [again.position, again.du, again.dv],
            "{faces} faces"
        );
        let normal = |d: &trispline::surface::Derivatives| d.du.cross(d.dv).normalize();
        let sc = scale(&m);
        let hair = 1e-12;
        let near = eval(&first, &m, 0, 1.0 - hair, 0.5 * hair);
        assert!(
            (near.position - at.position).length() <= 1e-12 * sc,
            "{faces}"
        );
        assert!(normal(&near).angle_between(normal(&at)) < 1e-9, "{faces}");
        // Outside the snap the descent answers: the point is off the vertex.
        let inside = 1e-6;
        let off = eval(&first, &m, 0, 1.0 - inside, 0.5 * inside);
        let gap = (off.position - at.position).length() / sc;
        assert!(gap > 1e-9 && gap < 1e-4, "{faces} faces: {gap:e}");
    }
}

#[test]
fn a_step_out_of_a_corner_between_two_boundary_edges_stays_at_the_corner() {
    // A square of two faces: vertex 1 lies on face 0 alone, between two boundary edges.
    let faces = [[0, 1, 2], [0, 2, 3]];
    let s = LoopLimitSurface::new(4, &faces).expect("a disk");
    let at = |face: u32, u: f64, v: f64| SurfaceParam { face, u, v };
    // Out of both edges at the corner (u, v) = (0, 1): each slide along one edge points
    // out of the other, so the point is pinned there.
    let q = s.step(at(0, 0.0, 1.0), -0.3, 0.3);
    assert_eq!((q.face, q.u, q.v), (0, 0.0, 1.0), "{q:?}");
    // Along one of the two edges, inwards: it slides away from the corner.
    let q = s.step(at(0, 0.0, 1.0), 0.2, -0.2);
    assert_eq!(q.face, 0);
    assert!(
        (q.u - 0.2).abs() < 1e-15 && (q.v - 0.8).abs() < 1e-15,
        "{q:?}"
    );
    // On a boundary edge, out of it and along it: one zero-length slide, then the point
    // moves along the edge.
    let q = s.step(at(0, 0.0, 0.5), -0.2, 0.3);
    assert_eq!(q.face, 0);
    assert!(q.u.abs() < 1e-15 && (q.v - 0.7).abs() < 1e-12, "{q:?}");
    // From inside, onto a boundary edge and along it towards the corner, short of it: one
    // slide after a move, not pinned.
    let q = s.step(at(0, 0.2, 0.6), -0.5, 0.5);
    assert_eq!(q.face, 0);
    assert!(q.u.abs() < 1e-15 && (q.v - 0.95).abs() < 1e-12, "{q:?}");
    // Far past the corner from inside: it reaches the corner and stays.
    let q = s.step(at(0, 0.2, 0.6), -2.0, 2.0);
    assert_eq!((q.face, q.u, q.v), (0, 0.0, 1.0), "{q:?}");
}
