//! The Loop limit surface against Loop subdivision itself, the box spline, the boundary
//! B-spline, finite differences and its own continuity. Meshes are generated here.

use glam::DVec3;
use std::collections::HashMap;
use trispline::mesh::loop_subdiv::{loop_beta, loop_step};
use trispline::mesh::topology::{Topology, NONE};
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::surface::box_spline::LatticeSpline;
use trispline::surface::loop_limit::LoopLimitSurface;
use trispline::surface::{BasisDerivRows, Derivatives, SurfaceParam, TriSurface};

pub(crate) struct Rng(pub(crate) u64);

impl Rng {
    pub(crate) fn f(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    pub(crate) fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f()
    }
}

pub(crate) struct Mesh {
    pub(crate) name: String,
    pub(crate) pos: Vec<DVec3>,
    pub(crate) tris: Vec<[u32; 3]>,
}

pub(crate) fn bump(pos: &mut [DVec3], seed: u64) {
    let mut r = Rng(seed);
    for p in pos.iter_mut() {
        *p += DVec3::new(r.range(-0.1, 0.1), r.range(-0.1, 0.1), r.range(-0.3, 0.3));
    }
}

/// `sectors` lattice triangles of size `k` around a centre vertex: closed (centre of
/// valence `sectors`) or an open fan (centre on the boundary with `sectors` faces per
/// ring step). Boundary vertices where two sectors meet have 2 faces.
pub(crate) fn polar(sectors: usize, k: usize, closed: bool, seed: u64) -> Mesh {
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

pub(crate) fn tetrahedron() -> Mesh {
    let mut pos = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
    bump(&mut pos, 3);
    Mesh {
        name: "tetrahedron".into(),
        pos,
        tris: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    }
}

pub(crate) fn octahedron() -> Mesh {
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

pub(crate) fn icosahedron() -> Mesh {
    let (mut pos, tris) = trispline::testdata::icosahedron();
    bump(&mut pos, 7);
    Mesh {
        name: "icosahedron".into(),
        pos,
        tris,
    }
}

pub(crate) fn lattice(m: usize, seed: u64) -> Mesh {
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

pub(crate) fn scale(m: &Mesh) -> f64 {
    let (lo, hi) = m.pos.iter().fold(
        (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    (hi - lo).length()
}

pub(crate) fn surface(m: &Mesh) -> LoopLimitSurface {
    LoopLimitSurface::new(m.pos.len(), &m.tris).expect("test meshes are manifold")
}

pub(crate) fn eval(s: &LoopLimitSurface, m: &Mesh, face: usize, u: f64, v: f64) -> Derivatives {
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
pub(crate) fn limit_positions(topo: &Topology, pos: &[DVec3]) -> Vec<DVec3> {
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
pub(crate) struct Fine {
    pub(crate) pos: Vec<DVec3>,
    pub(crate) tris: Vec<[u32; 3]>,
    pub(crate) origin: Vec<(usize, [[f64; 3]; 3])>,
}

pub(crate) fn subdivide(m: &Mesh, levels: usize) -> Fine {
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

pub(crate) fn meshes_with_extraordinary_vertices() -> Vec<Mesh> {
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
pub(crate) fn equals_limit_masks_of_the_subdivided_mesh_at_dyadic_parameters() {
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
pub(crate) fn regular_faces_are_the_quartic_box_spline() {
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
pub(crate) fn dir(e: &Derivatives, d: [f64; 3]) -> DVec3 {
    e.du * d[0] + e.dv * d[1]
}

pub(crate) fn unit(k: usize) -> [f64; 3] {
    let mut e = [0.0; 3];
    e[k] = 1.0;
    e
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn bary_param(b: [f64; 3]) -> (f64, f64) {
    (b[0], b[1])
}

#[test]
pub(crate) fn continuous_with_first_derivatives_across_shared_edges() {
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
