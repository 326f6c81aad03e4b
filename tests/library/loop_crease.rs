//! Crease edges in the Loop limit surface (Hoppe et al. 1994) against forward subdivision
//! with the crease rules, the cubic B-spline along a regular crease, a cube whose limit
//! surface must keep its right angles, finite differences and the partition of unity.

use glam::DVec3;
use std::collections::{HashMap, HashSet};
use trispline::mesh::loop_subdiv::{loop_beta, loop_step_with_creases};
use trispline::mesh::topology::Topology;
use trispline::surface::bezier::{lattice_points, lattice_triangles};
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

struct Creased {
    name: &'static str,
    pos: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
    creases: Vec<[u32; 2]>,
}

impl Creased {
    fn surface(&self) -> LoopLimitSurface {
        LoopLimitSurface::with_creases(self.pos.len(), &self.tris, &self.creases)
            .expect("test meshes are manifold and their creases are edges")
    }

    fn scale(&self) -> f64 {
        let (lo, hi) = self.pos.iter().fold(
            (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        (hi - lo).length()
    }
}

fn eval(s: &LoopLimitSurface, pos: &[DVec3], face: usize, u: f64, v: f64) -> Derivatives {
    s.evaluate(
        pos,
        SurfaceParam {
            face: face as u32,
            u,
            v,
        },
    )
}

/// Triangular lattice of size `n`, bumped, with a crease along row `j = 3` from boundary
/// to boundary (corners at both ends, regular crease vertices between) and a crease from
/// the boundary into the interior along row `j = 6` ending in a dart.
fn lattice(n: usize, seed: u64) -> Creased {
    let pts = lattice_points(n);
    let index: HashMap<(usize, usize), u32> = pts
        .iter()
        .enumerate()
        .map(|(k, &ij)| (ij, k as u32))
        .collect();
    let h = 3f64.sqrt() / 2.0;
    let mut r = Rng(seed);
    let pos = pts
        .iter()
        .map(|&(i, j)| DVec3::new(i as f64 + 0.5 * j as f64, h * j as f64, r.range(-0.4, 0.4)))
        .collect();
    let mut creases = Vec::new();
    for i in 0..n - 3 {
        creases.push([index[&(i, 3)], index[&(i + 1, 3)]]);
    }
    for i in 0..2 {
        creases.push([index[&(i, 6)], index[&(i + 1, 6)]]);
    }
    Creased {
        name: "lattice",
        pos,
        tris: lattice_triangles(n),
        creases,
    }
}

/// A bumped icosahedron with a crease chain 0-5-4 (darts at 0 and 4, a crease vertex of
/// valence 5 between), a crease loop 1-7-8 and a corner at 3 (three crease edges).
fn icosahedron() -> Creased {
    let mut r = Rng(7);
    let (corners, tris) = trispline::testdata::icosahedron();
    let pos = corners
        .into_iter()
        .map(|p| p + DVec3::new(r.range(-0.2, 0.2), r.range(-0.2, 0.2), 0.0))
        .collect();
    Creased {
        name: "icosahedron",
        pos,
        tris,
        creases: vec![
            [0, 5],
            [5, 4],
            [1, 7],
            [7, 8],
            [8, 1],
            [3, 9],
            [2, 3],
            [3, 6],
        ],
    }
}

/// An axis-aligned cube of side 1 with an `n` x `n` grid on every face (each cell split
/// along one diagonal), the 12 cube edges creased; `jitter` moves vertices within their
/// face plane only.
fn cube(n: usize, jitter: f64, seed: u64) -> Creased {
    let mut r = Rng(seed);
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let mut pos: Vec<DVec3> = Vec::new();
    let mut tris = Vec::new();
    let mut on_edge: Vec<u8> = Vec::new();
    // (normal axis, side, the two in-plane axes in counter-clockwise order seen from out).
    for axis in 0..3 {
        for side in [0i64, 1] {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let (a, b) = if side == 1 { (a, b) } else { (b, a) };
            let mut grid = vec![vec![0u32; n + 1]; n + 1];
            for (i, row) in grid.iter_mut().enumerate() {
                for (j, slot) in row.iter_mut().enumerate() {
                    let mut key = [0i64; 3];
                    key[axis] = side * n as i64;
                    key[a] = i as i64;
                    key[b] = j as i64;
                    *slot = *ids.entry(key).or_insert_with(|| {
                        let ext = key.iter().filter(|&&k| k == 0 || k == n as i64).count();
                        let mut p =
                            DVec3::new(key[0] as f64, key[1] as f64, key[2] as f64) / n as f64;
                        // Interior grid vertices move within the face plane.
                        if ext == 1 {
                            p[a] += r.range(-jitter, jitter) / n as f64;
                            p[b] += r.range(-jitter, jitter) / n as f64;
                        }
                        pos.push(p);
                        on_edge.push(ext as u8);
                        (pos.len() - 1) as u32
                    });
                }
            }
            for i in 0..n {
                for j in 0..n {
                    let (p, q, s, t) = (
                        grid[i][j],
                        grid[i + 1][j],
                        grid[i + 1][j + 1],
                        grid[i][j + 1],
                    );
                    tris.push([p, q, s]);
                    tris.push([p, s, t]);
                }
            }
        }
    }
    let topo = Topology::build(pos.len(), &tris).expect("the cube is manifold");
    let creases = topo
        .edges()
        .into_iter()
        .filter(|&(a, b, _)| {
            let (pa, pb) = (pos[a as usize], pos[b as usize]);
            // Both on one cube edge: two coordinates shared and extreme.
            on_edge[a as usize] >= 2
                && on_edge[b as usize] >= 2
                && (0..3)
                    .filter(|&k| pa[k] == pb[k] && (pa[k] == 0.0 || pa[k] == 1.0))
                    .count()
                    >= 2
        })
        .map(|(a, b, _)| [a, b])
        .collect();
    Creased {
        name: "cube",
        pos,
        tris,
        creases,
    }
}

/// Limit positions of a mesh with creases: Loop's mask where smooth, 2/3 1/6 1/6 along
/// two sharp edges, the vertex itself at a corner, and at a dart the fixed point of its
/// 1-ring's subdivision (iterated here).
fn limit_positions(topo: &Topology, pos: &[DVec3], creases: &HashSet<(u32, u32)>) -> Vec<DVec3> {
    let is_crease = |a: u32, b: u32| creases.contains(&(a.min(b), a.max(b)));
    (0..pos.len() as u32)
        .map(|v| {
            let ring = topo.ring(v);
            let p = |i: u32| pos[i as usize];
            if topo.is_boundary(v) {
                let inner_crease = ring[1..ring.len() - 1].iter().any(|&r| is_crease(v, r));
                if topo.is_corner(v) || inner_crease {
                    return p(v);
                }
                return p(v) * (2.0 / 3.0) + (p(ring[0]) + p(ring[ring.len() - 1])) / 6.0;
            }
            let sharp: Vec<bool> = ring.iter().map(|&r| is_crease(v, r)).collect();
            let ends: Vec<u32> = ring.iter().copied().filter(|&r| is_crease(v, r)).collect();
            let n = ring.len();
            match ends.len() {
                0 => {
                    let chi = 1.0 / (3.0 / (8.0 * loop_beta(n)) + n as f64);
                    p(v) * (1.0 - n as f64 * chi) + ring.iter().map(|&j| p(j)).sum::<DVec3>() * chi
                }
                1 => {
                    // Positions of the 1-ring subdivided many times; the centre converges.
                    let beta = loop_beta(n);
                    let mut c = p(v);
                    let mut rr: Vec<DVec3> = ring.iter().map(|&j| p(j)).collect();
                    for _ in 0..300 {
                        let nc = c * (1.0 - n as f64 * beta) + rr.iter().sum::<DVec3>() * beta;
                        let nr: Vec<DVec3> = (0..n)
                            .map(|j| {
                                if sharp[j] {
                                    (c + rr[j]) * 0.5
                                } else {
                                    (c + rr[j]) * 0.375
                                        + (rr[(j + 1) % n] + rr[(j + n - 1) % n]) * 0.125
                                }
                            })
                            .collect();
                        (c, rr) = (nc, nr);
                    }
                    c
                }
                2 => p(v) * (2.0 / 3.0) + (p(ends[0]) + p(ends[1])) / 6.0,
                _ => p(v),
            }
        })
        .collect()
}

fn meshes() -> Vec<Creased> {
    vec![lattice(8, 3), icosahedron(), cube(3, 0.2, 5)]
}

#[test]
fn creased_surface_equals_limit_masks_of_crease_subdivision_at_dyadic_parameters() {
    let mut worst = 0.0f64;
    for m in meshes() {
        let s = m.surface();
        assert!(!s.crease_edges().is_empty());
        let sc = m.scale();
        let mid = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]));
        let (mut pos, mut tris, mut creases) = (m.pos.clone(), m.tris.clone(), m.creases.clone());
        let mut origin: Vec<(usize, [[f64; 3]; 3])> = (0..m.tris.len())
            .map(|i| (i, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
            .collect();
        for level in 1..=3 {
            let topo = Topology::build(pos.len(), &tris).expect("manifold");
            let (st, fine_creases) = loop_step_with_creases(&topo, &creases);
            let mut next = Vec::with_capacity(4 * origin.len());
            for &(c, [b0, b1, b2]) in &origin {
                let (m0, m1, m2) = (mid(b0, b1), mid(b1, b2), mid(b2, b0));
                next.extend([
                    (c, [b0, m0, m2]),
                    (c, [b1, m1, m0]),
                    (c, [b2, m2, m1]),
                    (c, [m0, m1, m2]),
                ]);
            }
            (pos, tris, creases, origin) =
                (st.operator.apply(&pos), st.triangles, fine_creases, next);
            let topo = Topology::build(pos.len(), &tris).expect("manifold");
            let set: HashSet<(u32, u32)> =
                creases.iter().map(|&[a, b]| (a.min(b), a.max(b))).collect();
            let lim = limit_positions(&topo, &pos, &set);
            let mut err = 0.0f64;
            for (t, &(c, bary)) in tris.iter().zip(&origin) {
                for k in 0..3 {
                    let e = eval(&s, &m.pos, c, bary[k][0], bary[k][1]);
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
    println!("creased dyadic limit masks: max relative deviation {worst:e}");
}

#[test]
fn a_regular_crease_is_the_uniform_cubic_bspline_of_its_polygon() {
    let n = 10;
    let m = lattice(n, 9);
    let s = m.surface();
    let pts = lattice_points(n);
    let index: HashMap<(usize, usize), u32> = pts
        .iter()
        .enumerate()
        .map(|(k, &ij)| (ij, k as u32))
        .collect();
    let poly: Vec<u32> = (0..=n - 3).map(|i| index[&(i, 3)]).collect();
    let mut worst = 0.0f64;
    let mut checked = 0;
    // Segments whose four B-spline controls are all crease vertices (not the corners).
    for k in 2..poly.len() - 3 {
        let (a, b) = (poly[k], poly[k + 1]);
        let (f, t) = m
            .tris
            .iter()
            .enumerate()
            .find(|(_, t)| t.contains(&a) && t.contains(&b))
            .expect("a crease edge has a face");
        let slot = |x: u32| t.iter().position(|&c| c == x).expect("corner");
        for step in 0..=8 {
            let w = step as f64 / 8.0;
            let mut bary = [0.0; 3];
            bary[slot(a)] = 1.0 - w;
            bary[slot(b)] = w;
            let got = eval(&s, &m.pos, f, bary[0], bary[1]).position;
            let p = |i: usize| m.pos[poly[i] as usize];
            let want = p(k - 1) * ((1.0 - w).powi(3) / 6.0)
                + p(k) * ((3.0 * w.powi(3) - 6.0 * w * w + 4.0) / 6.0)
                + p(k + 1) * ((-3.0 * w.powi(3) + 3.0 * w * w + 3.0 * w + 1.0) / 6.0)
                + p(k + 2) * (w.powi(3) / 6.0);
            worst = worst.max((got - want).length() / m.scale());
            checked += 1;
        }
    }
    assert!(checked >= 18);
    assert!(worst < 1e-12, "crease B-spline deviation {worst:e}");
    println!("crease B-spline: max relative deviation {worst:e} over {checked} points");
}

fn angle_deg(a: DVec3, b: DVec3) -> f64 {
    a.angle_between(b).to_degrees()
}

/// Normals of the two faces of each crease edge at points along it.
fn crease_angles(m: &Creased, s: &LoopLimitSurface) -> Vec<f64> {
    let mut out = Vec::new();
    for &[a, b] in s.crease_edges() {
        let faces: Vec<usize> = (0..m.tris.len())
            .filter(|&f| m.tris[f].contains(&a) && m.tris[f].contains(&b))
            .collect();
        assert_eq!(faces.len(), 2);
        for w in [0.25, 0.5, 0.75] {
            let normal = |f: usize| {
                let t = m.tris[f];
                let mut bary = [0.0; 3];
                bary[t.iter().position(|&c| c == a).expect("corner")] = 1.0 - w;
                bary[t.iter().position(|&c| c == b).expect("corner")] = w;
                let e = eval(s, &m.pos, f, bary[0], bary[1]);
                (e.position, e.du.cross(e.dv))
            };
            let ((p0, n0), (p1, n1)) = (normal(faces[0]), normal(faces[1]));
            assert!(
                (p0 - p1).length() < 1e-12,
                "the surface is continuous across a crease"
            );
            out.push(angle_deg(n0, n1));
        }
    }
    out
}

#[test]
fn a_creased_cube_keeps_its_right_angles_and_an_uncreased_one_is_rounded() {
    let m = cube(4, 0.2, 11);
    assert_eq!(m.creases.len(), 12 * 4);
    let s = m.surface();
    assert_eq!(s.crease_edges().len(), 48);
    let angles = crease_angles(&m, &s);
    let off = angles
        .iter()
        .map(|a| (a - 90.0).abs())
        .fold(0.0f64, f64::max);
    assert!(
        off < 1e-6,
        "normals across a cube edge {off} degrees off 90"
    );
    // Every face stays in its cube face's plane: the limit is the cube itself.
    let mut r = Rng(3);
    let mut plane_off = 0.0f64;
    for f in 0..m.tris.len() {
        let u = r.f();
        let v = r.f() * (1.0 - u);
        let p = eval(&s, &m.pos, f, u, v).position;
        let c = m.tris[f].map(|i| m.pos[i as usize]);
        let axis = (0..3)
            .find(|&k| c[0][k] == c[1][k] && c[1][k] == c[2][k])
            .expect("a cube face triangle has a constant coordinate");
        plane_off = plane_off.max((p[axis] - c[0][axis]).abs());
    }
    assert!(plane_off < 1e-12, "a face left its plane by {plane_off:e}");
    // Without creases the same control mesh is rounded off.
    let smooth = LoopLimitSurface::new(m.pos.len(), &m.tris).expect("manifold");
    let mut rounded = Vec::new();
    for &[a, b] in s.crease_edges() {
        let faces: Vec<usize> = (0..m.tris.len())
            .filter(|&f| m.tris[f].contains(&a) && m.tris[f].contains(&b))
            .collect();
        let n = |f: usize| {
            let t = m.tris[f];
            let mut bary = [0.0; 3];
            bary[t.iter().position(|&c| c == a).expect("corner")] = 0.5;
            bary[t.iter().position(|&c| c == b).expect("corner")] = 0.5;
            let e = eval(&smooth, &m.pos, f, bary[0], bary[1]);
            e.du.cross(e.dv)
        };
        rounded.push(angle_deg(n(faces[0]), n(faces[1])));
    }
    let most = rounded.iter().fold(0.0f64, |a, &b| a.max(b));
    assert!(
        most < 1.0,
        "without creases the limit is C1 (normal jump {most})"
    );
    println!("creased cube: |angle - 90| <= {off:e} deg, plane deviation {plane_off:e}");
}

#[test]
fn creased_derivatives_match_central_differences_and_rows_sum_right() {
    let mut r = Rng(29);
    let hh = 1e-5;
    let (mut w1, mut w2) = (0.0f64, 0.0f64);
    let mut rows = BasisDerivRows::default();
    let mut worst_sum = (0.0f64, 0.0f64);
    for m in meshes() {
        let s = m.surface();
        for f in 0..m.tris.len() {
            for _ in 0..3 {
                let u = r.range(0.05, 0.9);
                let v = r.range(0.05, 0.95 - u);
                let e = eval(&s, &m.pos, f, u, v);
                let at = |du: f64, dv: f64| eval(&s, &m.pos, f, u + du, v + dv);
                let (pu, nu, pv, nv) = (at(hh, 0.0), at(-hh, 0.0), at(0.0, hh), at(0.0, -hh));
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
                    / sz2;
                assert!(
                    d1 < 1e-7 && d2 < 1e-5,
                    "{} face {f}: first {d1:e} second {d2:e}",
                    m.name
                );
                (w1, w2) = (w1.max(d1), w2.max(d2));
            }
            for (u, v) in [(1.0, 0.0), (0.0, 1.0), (0.0, 0.0), (0.5, 0.5), (0.3, 0.2)] {
                s.basis_rows_with_derivatives(
                    SurfaceParam {
                        face: f as u32,
                        u,
                        v,
                    },
                    &mut rows,
                );
                let mut sum = [0.0; 6];
                for w in &rows.weights {
                    for d in 0..6 {
                        assert!(w[d].is_finite(), "{} face {f}: {w:?}", m.name);
                        sum[d] += w[d];
                    }
                }
                worst_sum.0 = worst_sum.0.max((sum[0] - 1.0).abs());
                worst_sum.1 = worst_sum
                    .1
                    .max(sum[1..].iter().fold(0.0f64, |a, x| a.max(x.abs())));
                // The rows are the evaluation.
                let e = eval(&s, &m.pos, f, u, v);
                let p: DVec3 = rows
                    .indices
                    .iter()
                    .zip(&rows.weights)
                    .map(|(&i, w)| m.pos[i as usize] * w[0])
                    .sum();
                assert!((p - e.position).length() < 1e-12 * m.scale());
            }
        }
    }
    assert!(
        worst_sum.0 < 1e-13 && worst_sum.1 < 1e-9,
        "row sums {worst_sum:?}"
    );
    println!("creased finite differences: first {w1:e}, second {w2:e}; row sums {worst_sum:?}");
}

#[test]
fn a_crease_that_is_no_edge_is_refused() {
    let m = icosahedron();
    let err = LoopLimitSurface::with_creases(m.pos.len(), &m.tris, &[[0, 3]])
        .expect_err("0-3 is no edge");
    assert_eq!(err.kind(), "unknown_crease_edge");
    assert!(matches!(
        err,
        LoopLimitError::UnknownCreaseEdge { a: 0, b: 3 }
    ));
    let err = LoopLimitSurface::with_creases(m.pos.len(), &m.tris, &[[0, 99]])
        .expect_err("99 is no vertex");
    assert_eq!(err.kind(), "unknown_crease_edge");
}
