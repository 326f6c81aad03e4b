//! Mesh-core timings on ~1M faces (prints figures; best of 5):
//! load a binary PLY, build topology, one level of detection + exact inverse Loop.
//!
//! Run: cargo run --release --example bench_mesh

use std::time::Instant;
use trispline::io::writers::ply_bytes;
use trispline::io::{read_mesh_bytes, Format, LoadOptions};
use trispline::mesh::detect::detect_level;
use trispline::mesh::inverse::exact_inverse_operator;
use trispline::mesh::loop_subdiv::subdivide;
use trispline::mesh::topology::Topology;
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::{DVec3, TriMesh};

fn best_of<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::MAX;
    let mut last = None;
    for _ in 0..runs {
        let t = Instant::now();
        let out = f();
        best = best.min(t.elapsed().as_secs_f64());
        last = Some(out);
    }
    (best, last.expect("at least one run"))
}

fn main() {
    // A 1000-segment triangular lattice: 1,000,000 faces, made by subdividing a
    // 250-lattice twice so that it also has Loop subdivision connectivity.
    let coarse_n = 250;
    let coarse = TriMesh::new(
        lattice_points(coarse_n)
            .into_iter()
            .map(|(i, j)| {
                let (u, v) = (i as f64 / coarse_n as f64, j as f64 / coarse_n as f64);
                DVec3::new(u, v, (6.0 * u).sin() * (4.0 * v).cos() * 0.1)
            })
            .collect(),
        lattice_triangles(coarse_n),
    );
    let mesh = subdivide(&coarse, 2).expect("lattice is manifold");
    let bytes = ply_bytes(&mesh);
    println!(
        "mesh: {} vertices, {} faces; binary PLY {:.1} MB",
        mesh.positions.len(),
        mesh.triangles.len(),
        bytes.len() as f64 / 1e6
    );
    let (t_load, loaded) = best_of(5, || {
        read_mesh_bytes(&bytes, Format::Ply, "bench.ply", &LoadOptions::default()).expect("reads")
    });
    assert_eq!(loaded.mesh.triangles.len(), mesh.triangles.len());
    println!(
        "load binary PLY:          {:7.1} ms (target < 500 ms)",
        t_load * 1e3
    );
    let (t_topo, topo) = best_of(5, || Topology::from_mesh(&mesh).expect("manifold"));
    println!(
        "build topology:           {:7.1} ms (target < 300 ms)",
        t_topo * 1e3
    );
    let (t_detect, level) = best_of(5, || detect_level(&topo, 1).expect("subdivided"));
    let (t_inverse, coarse_pos) = best_of(5, || {
        exact_inverse_operator(&topo, &level).apply(&mesh.positions)
    });
    println!("detect one level:         {:7.1} ms", t_detect * 1e3);
    println!("exact inverse (apply):    {:7.1} ms", t_inverse * 1e3);
    println!(
        "one level inverse Loop:   {:7.1} ms (target < 200 ms; detection + inverse)",
        (t_detect + t_inverse) * 1e3
    );
    println!("coarse vertices: {}", coarse_pos.len());
}
