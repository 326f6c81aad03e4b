//! The Loop limit surface against Loop subdivision itself, the box spline, the boundary
//! B-spline, finite differences and its own continuity. Meshes are generated here.

use glam::DVec3;
use std::collections::HashMap;
use trispline::mesh::loop_subdiv::{loop_beta, loop_step};
use trispline::mesh::topology::{Topology, NONE};
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::surface::box_spline::LatticeSpline;
use trispline::surface::loop_limit::{LoopLimitError, LoopLimitSurface};
use trispline::surface::{BasisDerivRows, Derivatives, SurfaceParam, TriSurface};

struct Rng(u64);

impl Rng {
    fn f(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f()
    }
}

struct Mesh {
    name: String,
    pos: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
}

fn bump(pos: &mut [DVec3], seed: u64) {
    let mut r = Rng(seed);
    for p in pos.iter_mut() {
        *p += DVec3::new(r.range(-0.1, 0.1), r.range(-0.1, 0.1), r.range(-0.3, 0.3));
    }
}

/// `sectors` lattice triangles of size `k` around a centre vertex: closed (centre of
/// valence `sectors`) or an open fan (centre on the boundary with `sectors` faces per
/// ring step). Boundary vertices where two sectors meet have 2 faces.
fn polar(sectors: usize, k: usize, closed: bool, seed: u64) -> Mesh {
    let spokes = if closed { sectors } else { sectors + 1 };
    let step = if closed {
        2.0 * std::f64::consts::PI / sectors as f64
    } else {
        (2.0 * std::f64::consts::PI / (sectors + 1) as f64).min(std::f64::consts::PI / 3.0)
    };
    let dir = |s: usize| DVec3::new((s as f64 * step).cos(), (s as f64 * step).sin(), 0.0);
    let mut ids: HashMap<(usize, usize, usize), u32> = HashMap::new();
    let mut pos = Vec::new();
    let mut id = |s: usize, i: usize, j: usize, pos: &mut Vec<DVec3>| -> u32 {
        let key = if i == 0 && j == 0 {
            (usize::MAX, 0, 0)
        } else if j == 0 {
            (s, i, 0)
        } else if i == 0 {
            ((s + 1) % spokes, j, 0)
        } else {
            (s, i, j)
        };
        *ids.entry(key).or_insert_with(|| {
            pos.push(dir(s) * i as f64 + dir(s + 1) * j as f64);
            (pos.len() - 1) as u32
        })
    };
    let mut tris = Vec::new();
    for s in 0..sectors {
        for j in 0..k {
            for i in 0..k - j {
                tris.push([
                    id(s, i, j, &mut pos),
                    id(s, i + 1, j, &mut pos),
                    id(s, i, j + 1, &mut pos),
                ]);
                if i + j + 1 < k {
                    tris.push([
                        id(s, i + 1, j, &mut pos),
                        id(s, i + 1, j + 1, &mut pos),
                        id(s, i, j + 1, &mut pos),
                    ]);
                }
            }
        }
    }
    bump(&mut pos, seed);
    Mesh {
        name: format!(
            "{} {sectors}x{k}",
            if closed { "polar" } else { "open fan" }
        ),
        pos,
        tris,
    }
}

fn tetrahedron() -> Mesh {
    let mut pos = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
    bump(&mut pos, 3);
    Mesh {
        name: "tetrahedron".into(),
        pos,
        tris: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    }
}

fn octahedron() -> Mesh {
    let mut pos = vec![
        DVec3::X,
        DVec3::Y,
        -DVec3::X,
        -DVec3::Y,
        DVec3::Z,
        -DVec3::Z,
    ];
    bump(&mut pos, 5);
    let mut tris = Vec::new();
    for i in 0..4u32 {
        tris.push([i, (i + 1) % 4, 4]);
        tris.push([(i + 1) % 4, i, 5]);
    }
    Mesh {
        name: "octahedron".into(),
        pos,
        tris,
    }
}

fn icosahedron() -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<DVec3> = [
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
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z))
    .collect();
    bump(&mut pos, 7);
    let tris = vec![
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
    Mesh {
        name: "icosahedron".into(),
        pos,
        tris,
    }
}

fn lattice(m: usize, seed: u64) -> Mesh {
    let h = 3f64.sqrt() / 2.0;
    let mut pos: Vec<DVec3> = lattice_points(m)
        .into_iter()
        .map(|(i, j)| DVec3::new(i as f64 + 0.5 * j as f64, h * j as f64, 0.0))
        .collect();
    let mut r = Rng(seed);
    for p in pos.iter_mut() {
        p.z = r.range(-0.4, 0.4);
    }
    Mesh {
        name: format!("lattice {m}"),
        pos,
        tris: lattice_triangles(m),
    }
}

fn scale(m: &Mesh) -> f64 {
    let (lo, hi) = m.pos.iter().fold(
        (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    (hi - lo).length()
}

fn surface(m: &Mesh) -> LoopLimitSurface {
    LoopLimitSurface::new(m.pos.len(), &m.tris).expect("test meshes are manifold")
}

fn eval(s: &LoopLimitSurface, m: &Mesh, face: usize, u: f64, v: f64) -> Derivatives {
    s.evaluate(
        &m.pos,
        SurfaceParam {
            face: face as u32,
            u,
            v,
        },
    )
}

/// Loop's limit-position mask at every vertex (interior chi, boundary 2/3 1/6 1/6,
/// corner itself).
fn limit_positions(topo: &Topology, pos: &[DVec3]) -> Vec<DVec3> {
    (0..pos.len() as u32)
        .map(|v| {
            let ring = topo.ring(v);
            if topo.is_boundary(v) {
                if topo.is_corner(v) {
                    pos[v as usize]
                } else {
                    pos[v as usize] * (2.0 / 3.0)
                        + (pos[ring[0] as usize] + pos[ring[ring.len() - 1] as usize]) / 6.0
                }
            } else {
                let n = ring.len();
                let chi = 1.0 / (3.0 / (8.0 * loop_beta(n)) + n as f64);
                pos[v as usize] * (1.0 - n as f64 * chi)
                    + ring.iter().map(|&j| pos[j as usize]).sum::<DVec3>() * chi
            }
        })
        .collect()
}

/// The mesh subdivided `levels` times, with each fine face's coarse face and the
/// barycentric coordinates of its corners there.
struct Fine {
    pos: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
    origin: Vec<(usize, [[f64; 3]; 3])>,
}

fn subdivide(m: &Mesh, levels: usize) -> Fine {
    let mut f = Fine {
        pos: m.pos.clone(),
        tris: m.tris.clone(),
        origin: (0..m.tris.len())
            .map(|i| (i, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
            .collect(),
    };
    let mid = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]));
    for _ in 0..levels {
        let topo = Topology::build(f.pos.len(), &f.tris).expect("manifold");
        let st = loop_step(&topo);
        let mut origin = Vec::with_capacity(4 * f.origin.len());
        for &(c, [b0, b1, b2]) in &f.origin {
            let (m0, m1, m2) = (mid(b0, b1), mid(b1, b2), mid(b2, b0));
            origin.push((c, [b0, m0, m2]));
            origin.push((c, [b1, m1, m0]));
            origin.push((c, [b2, m2, m1]));
            origin.push((c, [m0, m1, m2]));
        }
        f = Fine {
            pos: st.operator.apply(&f.pos),
            tris: st.triangles,
            origin,
        };
    }
    f
}

fn meshes_with_extraordinary_vertices() -> Vec<Mesh> {
    let mut v = vec![tetrahedron(), octahedron(), icosahedron()];
    for (n, seed) in [
        (3, 11),
        (4, 12),
        (5, 13),
        (7, 14),
        (8, 15),
        (12, 16),
        (16, 17),
    ] {
        v.push(polar(n, 2, true, seed));
    }
    for (m, seed) in [(1, 21), (2, 22), (4, 23), (5, 24), (7, 25)] {
        v.push(polar(m, 3, false, seed));
    }
    v.push(lattice(5, 31));
    // Every vertex a corner; two corners and two boundary vertices with 2 faces.
    let mut one = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
    bump(&mut one, 32);
    v.push(Mesh {
        name: "one triangle".into(),
        pos: one,
        tris: vec![[0, 1, 2]],
    });
    let mut two = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.0)];
    bump(&mut two, 33);
    v.push(Mesh {
        name: "two triangles".into(),
        pos: two,
        tris: vec![[0, 1, 2], [1, 3, 2]],
    });
    v
}

#[test]
fn equals_limit_masks_of_the_subdivided_mesh_at_dyadic_parameters() {
    let mut worst = 0.0f64;
    for m in meshes_with_extraordinary_vertices() {
        let s = surface(&m);
        let sc = scale(&m);
        let levels = if m.tris.len() > 40 { 3 } else { 4 };
        for level in 1..=levels {
            let f = subdivide(&m, level);
            let topo = Topology::build(f.pos.len(), &f.tris).expect("manifold");
            let lim = limit_positions(&topo, &f.pos);
            let mut err = 0.0f64;
            for (t, &(c, bary)) in f.tris.iter().zip(&f.origin) {
                for k in 0..3 {
                    let e = eval(&s, &m, c, bary[k][0], bary[k][1]);
                    err = err.max((e.position - lim[t[k] as usize]).length() / sc);
                }
            }
            assert!(
                err < 1e-12,
                "{} level {level}: relative error {err:e}",
                m.name
            );
            worst = worst.max(err);
        }
    }
    println!("dyadic limit masks: max relative deviation {worst:e}");
}

#[test]
fn regular_faces_are_the_quartic_box_spline() {
    let m = lattice(7, 41);
    let s = surface(&m);
    let ls = LatticeSpline::new(4);
    let coords: Vec<(f64, f64)> = lattice_points(7)
        .into_iter()
        .map(|(i, j)| (i as f64, j as f64))
        .collect();
    let topo = Topology::build(m.pos.len(), &m.tris).expect("manifold");
    let mut r = Rng(5);
    let mut worst = [0.0f64; 3];
    let mut checked = 0;
    for (f, t) in m.tris.iter().enumerate() {
        if t.iter().any(|&v| topo.is_boundary(v)) {
            continue;
        }
        for _ in 0..20 {
            let u = r.f();
            let v = r.f() * (1.0 - u);
            let w = 1.0 - u - v;
            let c = |k: usize| coords[t[k] as usize];
            let x = u * c(0).0 + v * c(1).0 + w * c(2).0;
            let y = u * c(0).1 + v * c(1).1 + w * c(2).1;
            let a = eval(&s, &m, f, u, v);
            let b = ls.evaluate(
                &m.pos,
                SurfaceParam {
                    face: 0,
                    u: (x - 1.0) / 4.0,
                    v: (y - 1.0) / 4.0,
                },
            );
            // Lattice-spline parameter per face parameter.
            let ju = ((c(0).0 - c(2).0) / 4.0, (c(0).1 - c(2).1) / 4.0);
            let jv = ((c(1).0 - c(2).0) / 4.0, (c(1).1 - c(2).1) / 4.0);
            let du = b.du * ju.0 + b.dv * ju.1;
            let dv = b.du * jv.0 + b.dv * jv.1;
            let h = |p: (f64, f64), q: (f64, f64)| {
                b.duu * p.0 * q.0 + b.duv * (p.0 * q.1 + p.1 * q.0) + b.dvv * p.1 * q.1
            };
            worst[0] = worst[0].max((a.position - b.position).length());
            worst[1] = worst[1].max((a.du - du).length().max((a.dv - dv).length()));
            worst[2] = worst[2].max(
                (a.duu - h(ju, ju))
                    .length()
                    .max((a.duv - h(ju, jv)).length())
                    .max((a.dvv - h(jv, jv)).length()),
            );
            checked += 1;
        }
    }
    assert!(checked > 100);
    assert!(worst.iter().all(|&e| e < 1e-11), "{worst:?}");
    println!("box spline: max deviation value/first/second {worst:?}");
}

/// Directional derivative for barycentric deltas (d0, d1, d2), summing to 0.
fn dir(e: &Derivatives, d: [f64; 3]) -> DVec3 {
    e.du * d[0] + e.dv * d[1]
}

fn unit(k: usize) -> [f64; 3] {
    let mut e = [0.0; 3];
    e[k] = 1.0;
    e
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn bary_param(b: [f64; 3]) -> (f64, f64) {
    (b[0], b[1])
}

#[test]
fn continuous_with_first_derivatives_across_shared_edges() {
    let mut r = Rng(9);
    let mut worst = (0.0f64, 0.0f64);
    for m in meshes_with_extraordinary_vertices() {
        let s = surface(&m);
        let sc = scale(&m);
        let topo = Topology::build(m.pos.len(), &m.tris).expect("manifold");
        for h in 0..topo.twin.len() {
            let tw = topo.twin[h];
            if tw == NONE || tw < h as u32 {
                continue;
            }
            let (f, j) = (h / 3, h % 3);
            let (k, i) = ((j + 1) % 3, (j + 2) % 3);
            let (g, gk) = ((tw / 3) as usize, (tw % 3) as usize);
            let (gj, go) = ((gk + 1) % 3, (gk + 2) % 3);
            for _ in 0..3 {
                let t = r.range(0.05, 0.95);
                let mut bf = [0.0; 3];
                bf[j] = 1.0 - t;
                bf[k] = t;
                let mut bg = [0.0; 3];
                bg[gj] = 1.0 - t;
                bg[gk] = t;
                let (a, b) = (bary_param(bf), bary_param(bg));
                let ef = eval(&s, &m, f, a.0, a.1);
                let eg = eval(&s, &m, g, b.0, b.1);
                let dp = (ef.position - eg.position).length() / sc;
                let along =
                    (dir(&ef, sub(unit(k), unit(j))) - dir(&eg, sub(unit(gk), unit(gj)))).length();
                let across =
                    (dir(&ef, sub(unit(i), unit(j))) - dir(&eg, sub(unit(gk), unit(go)))).length();
                let dd = along.max(across) / sc;
                assert!(
                    dp < 1e-12 && dd < 1e-9,
                    "{} faces {f}/{g} at {t}: value {dp:e}, derivative {dd:e}",
                    m.name
                );
                worst = (worst.0.max(dp), worst.1.max(dd));
            }
        }
    }
    println!(
        "across edges: max relative value gap {:e}, first-derivative gap {:e}",
        worst.0, worst.1
    );
}

#[test]
fn boundary_curve_is_the_uniform_cubic_bspline_of_the_boundary_polygon() {
    let mut r = Rng(13);
    let mut worst = 0.0f64;
    let mut checked = 0;
    let meshes = [
        polar(5, 2, true, 3),
        polar(7, 3, true, 4),
        polar(2, 3, false, 5),
        polar(4, 2, false, 6),
        lattice(5, 7),
    ];
    for m in &meshes {
        let s = surface(m);
        let sc = scale(m);
        let topo = Topology::build(m.pos.len(), &m.tris).expect("manifold");
        let other_end = |v: u32, not: u32| {
            let ring = topo.ring(v);
            if ring[0] == not {
                ring[ring.len() - 1]
            } else {
                ring[0]
            }
        };
        for h in 0..topo.twin.len() {
            if topo.twin[h] != NONE {
                continue;
            }
            let (f, j) = (h / 3, h % 3);
            let k = (j + 1) % 3;
            let (a, b) = (m.tris[f][j], m.tris[f][k]);
            if topo.is_corner(a) || topo.is_corner(b) {
                continue;
            }
            let p = [other_end(a, b), a, b, other_end(b, a)].map(|i| m.pos[i as usize]);
            for _ in 0..4 {
                let t = r.f();
                let mut bary = [0.0; 3];
                bary[j] = 1.0 - t;
                bary[k] = t;
                let e = eval(&s, m, f, bary[0], bary[1]);
                let bs = (p[0] * (1.0 - t).powi(3)
                    + p[1] * (3.0 * t.powi(3) - 6.0 * t * t + 4.0)
                    + p[2] * (-3.0 * t.powi(3) + 3.0 * t * t + 3.0 * t + 1.0)
                    + p[3] * t.powi(3))
                    / 6.0;
                let err = (e.position - bs).length() / sc;
                assert!(err < 1e-12, "{} face {f} t {t}: {err:e}", m.name);
                worst = worst.max(err);
                checked += 1;
            }
        }
    }
    assert!(checked > 50);
    println!("boundary B-spline: max relative deviation {worst:e} over {checked} points");
}

#[test]
fn derivatives_match_central_differences() {
    let mut r = Rng(17);
    let (mut w1, mut w2) = (0.0f64, 0.0f64);
    let meshes = [
        polar(3, 2, true, 1),
        polar(7, 2, true, 2),
        polar(12, 2, true, 3),
        polar(4, 2, false, 4),
        polar(1, 3, false, 5),
        icosahedron(),
    ];
    let hh = 1e-5;
    for m in &meshes {
        let s = surface(m);
        for f in 0..m.tris.len() {
            for _ in 0..3 {
                let u = r.range(0.05, 0.9);
                let v = r.range(0.05, 0.95 - u);
                let e = eval(&s, m, f, u, v);
                let (pu, nu) = (eval(&s, m, f, u + hh, v), eval(&s, m, f, u - hh, v));
                let (pv, nv) = (eval(&s, m, f, u, v + hh), eval(&s, m, f, u, v - hh));
                let c = |a: DVec3, b: DVec3| (a - b) / (2.0 * hh);
                let sz1 = 1.0 + e.du.length() + e.dv.length();
                let d1 = (c(pu.position, nu.position) - e.du)
                    .length()
                    .max((c(pv.position, nv.position) - e.dv).length())
                    / sz1;
                let sz2 = 1.0 + e.duu.length() + e.dvv.length();
                let d2 = (c(pu.du, nu.du) - e.duu)
                    .length()
                    .max((c(pv.dv, nv.dv) - e.dvv).length())
                    .max((c(pu.dv, nu.dv) - e.duv).length())
                    .max((c(pv.du, nv.du) - e.duv).length())
                    / sz2;
                assert!(
                    d1 < 1e-7 && d2 < 1e-5,
                    "{} face {f} ({u}, {v}): first {d1:e} second {d2:e}",
                    m.name
                );
                w1 = w1.max(d1);
                w2 = w2.max(d2);
            }
        }
    }
    println!("finite differences: max relative deviation first {w1:e}, second {w2:e}");
}

#[test]
fn basis_is_a_partition_of_unity_with_zero_sum_derivatives() {
    let mut r = Rng(23);
    let mut rows = BasisDerivRows::default();
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for m in meshes_with_extraordinary_vertices() {
        let s = surface(&m);
        for f in 0..m.tris.len() {
            let mut params = vec![(1.0, 0.0), (0.0, 1.0), (0.0, 0.0), (0.5, 0.5), (0.25, 0.0)];
            for _ in 0..5 {
                let u = r.f();
                params.push((u, r.f() * (1.0 - u)));
            }
            for (u, v) in params {
                s.basis_rows_with_derivatives(
                    SurfaceParam {
                        face: f as u32,
                        u,
                        v,
                    },
                    &mut rows,
                );
                let mut sum = [0.0; 6];
                let mut mag = [0.0f64; 6];
                for w in &rows.weights {
                    for d in 0..6 {
                        assert!(w[d].is_finite(), "{} face {f}: {w:?}", m.name);
                        sum[d] += w[d];
                        mag[d] = mag[d].max(w[d].abs());
                    }
                    worst.2 = worst.2.min(w[0]);
                }
                worst.0 = worst.0.max((sum[0] - 1.0).abs());
                for d in 1..6 {
                    let e = sum[d].abs() / (1.0 + mag[d]);
                    worst.1 = worst.1.max(e);
                }
            }
        }
    }
    assert!(worst.0 < 1e-13, "value sum off by {:e}", worst.0);
    assert!(worst.1 < 1e-11, "derivative sum {:e}", worst.1);
    assert!(worst.2 > -1e-14, "negative value weight {:e}", worst.2);
    println!(
        "partition of unity: |sum - 1| {:e}, derivative sums {:e}, min weight {:e}",
        worst.0, worst.1, worst.2
    );
}

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
