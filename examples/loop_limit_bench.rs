//! Basis rows per second of `LoopLimitSurface` on meshes full of extraordinary vertices,
//! at the dyadic parameters of subdivision levels 3 to 5 (where a fit's data points sit)
//! and at random parameters.
//!
//!     cargo run --release --example loop_limit_bench

use rayon::prelude::*;
use std::time::Instant;
use trispline::mesh::loop_subdiv::subdivide;
use trispline::surface::loop_limit::LoopLimitSurface;
use trispline::surface::{BasisDerivRows, SurfaceParam, TriSurface};
use trispline::{DVec3, TriMesh};

fn icosahedron() -> TriMesh {
    let (vertices, faces) = trispline::testdata::icosahedron();
    TriMesh::new(vertices, faces)
}

/// A disc of `n` lattice sectors of size `k` around a vertex of valence `n`.
fn polar(n: u32, k: u32) -> TriMesh {
    let mut ids = std::collections::HashMap::new();
    let mut pos = Vec::new();
    let mut id = |s: u32, i: u32, j: u32, pos: &mut Vec<DVec3>| -> u32 {
        let key = match (i, j) {
            (0, 0) => (u32::MAX, 0, 0),
            (_, 0) => (s, i, 0),
            (0, _) => ((s + 1) % n, j, 0),
            _ => (s, i, j),
        };
        *ids.entry(key).or_insert_with(|| {
            let a = |s: u32| {
                let t = 2.0 * std::f64::consts::PI * s as f64 / n as f64;
                DVec3::new(t.cos(), t.sin(), 0.0)
            };
            let q = a(s) * i as f64 + a(s + 1) * j as f64;
            pos.push(q + DVec3::Z * (0.3 * q.x).sin());
            (pos.len() - 1) as u32
        })
    };
    let mut tris = Vec::new();
    for s in 0..n {
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
    TriMesh::new(pos, tris)
}

fn dyadic_params(faces: usize, level: u32) -> Vec<SurfaceParam> {
    let n = 1u32 << level;
    let mut out = Vec::new();
    for f in 0..faces as u32 {
        for j in 0..=n {
            for i in 0..=n - j {
                out.push(SurfaceParam {
                    face: f,
                    u: i as f64 / n as f64,
                    v: j as f64 / n as f64,
                });
            }
        }
    }
    out
}

fn random_params(faces: usize, count: usize) -> Vec<SurfaceParam> {
    let mut x = 0x9e3779b97f4a7c15u64;
    let mut r = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..count)
        .map(|_| {
            let u = r();
            SurfaceParam {
                face: ((r() * faces as f64) as u32).min(faces as u32 - 1),
                u,
                v: r() * (1.0 - u),
            }
        })
        .collect()
}

/// Rows per second, single thread, and the checksum that keeps the work alive.
fn serial(s: &LoopLimitSurface, params: &[SurfaceParam]) -> (f64, f64) {
    let mut rows = BasisDerivRows::default();
    let mut check = 0.0;
    let t = Instant::now();
    for &p in params {
        s.basis_rows_with_derivatives(p, &mut rows);
        check += rows.weights.iter().map(|w| w[0]).sum::<f64>();
    }
    (params.len() as f64 / t.elapsed().as_secs_f64(), check)
}

fn parallel(s: &LoopLimitSurface, params: &[SurfaceParam]) -> f64 {
    let t = Instant::now();
    let total: usize = params
        .par_iter()
        .map_init(BasisDerivRows::default, |rows, &p| {
            s.basis_rows_with_derivatives(p, rows);
            rows.indices.len()
        })
        .sum();
    std::hint::black_box(total);
    params.len() as f64 / t.elapsed().as_secs_f64()
}

fn main() {
    let meshes = [
        (
            "icosahedron, 1 Loop step (12 valence-5)",
            subdivide(&icosahedron(), 1).expect("manifold"),
        ),
        ("disc around a valence-7 vertex", polar(7, 4)),
        ("disc around a valence-12 vertex", polar(12, 4)),
    ];
    println!("threads: {}", rayon::current_num_threads());
    for (name, m) in &meshes {
        let t = Instant::now();
        let s = LoopLimitSurface::new(m.positions.len(), &m.triangles).expect("manifold");
        println!(
            "\n{name}: {} faces, {} irregular, built in {:.2} ms",
            m.triangles.len(),
            s.irregular_face_count(),
            t.elapsed().as_secs_f64() * 1e3
        );
        for level in 3..=5 {
            let params = dyadic_params(m.triangles.len(), level);
            let (cold, _) = serial(&s, &params);
            let (warm, check) = serial(&s, &params);
            let par = parallel(&s, &params);
            println!(
                "  dyadic level {level}: {:>7} rows, first pass {:>10.0} rows/s, memoised {:>10.0} rows/s, rayon {:>10.0} rows/s (sum {:.1})",
                params.len(),
                cold,
                warm,
                par,
                check
            );
        }
        let irregular: Vec<SurfaceParam> = dyadic_params(m.triangles.len(), 5)
            .into_iter()
            .filter(|p| !s.is_regular_face(p.face as usize))
            .collect();
        let (rate, _) = serial(&s, &irregular);
        println!(
            "  dyadic level 5, irregular faces only: {:>7} rows, {:>10.0} rows/s",
            irregular.len(),
            rate
        );
        // Within 1e-9..1e-13 of corner 0 of face 0 (an extraordinary vertex in all three
        // meshes): descents of 30-45 levels, partly past the memoised depth.
        let near: Vec<SurfaceParam> = (0..2000)
            .map(|i| {
                let e = 10f64.powf(-9.0 - 4.0 * (i as f64 / 2000.0));
                SurfaceParam {
                    face: 0,
                    u: 1.0 - e,
                    v: 0.5 * e * (i % 7) as f64 / 7.0,
                }
            })
            .collect();
        let (rate, _) = serial(&s, &near);
        println!(
            "  within 1e-9..1e-13 of the extraordinary vertex: {:>7} rows, {:>10.0} rows/s",
            near.len(),
            rate
        );
        let params = random_params(m.triangles.len(), 200_000);
        let (rate, _) = serial(&s, &params);
        let par = parallel(&s, &params);
        println!(
            "  random: {:>7} rows, {:>10.0} rows/s, rayon {:>10.0} rows/s",
            params.len(),
            rate,
            par
        );
    }
}
