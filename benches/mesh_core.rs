//! Mesh-core benchmarks on 1M faces: binary PLY load, topology, one level of inverse Loop
//! (detection + exact inverse). Targets: < 0.5 s, < 0.3 s, < 0.2 s.
//! Run: cargo bench --bench mesh_core

use criterion::{criterion_group, criterion_main, Criterion};
use std::time::Duration;
use trispline::io::writers::ply_bytes;
use trispline::io::{read_mesh_bytes, Format, LoadOptions};
use trispline::mesh::detect::detect_level;
use trispline::mesh::inverse::exact_inverse_operator;
use trispline::mesh::loop_subdiv::subdivide;
use trispline::mesh::topology::Topology;
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::{DVec3, TriMesh};

fn million_faces() -> TriMesh {
    let n = 250;
    let coarse = TriMesh::new(
        lattice_points(n)
            .into_iter()
            .map(|(i, j)| {
                let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                DVec3::new(u, v, (6.0 * u).sin() * (4.0 * v).cos() * 0.1)
            })
            .collect(),
        lattice_triangles(n),
    );
    subdivide(&coarse, 2).expect("a lattice is manifold")
}

fn bench(c: &mut Criterion) {
    let mesh = million_faces();
    let bytes = ply_bytes(&mesh);
    let topo = Topology::from_mesh(&mesh).expect("manifold");
    let mut g = c.benchmark_group("mesh_core_1M_faces");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(200))
        .measurement_time(Duration::from_secs(3));
    g.bench_function("load_binary_ply", |b| {
        b.iter(|| {
            read_mesh_bytes(&bytes, Format::Ply, "bench.ply", &LoadOptions::default())
                .expect("reads")
        })
    });
    g.bench_function("build_topology", |b| {
        b.iter(|| Topology::from_mesh(&mesh).expect("manifold"))
    });
    g.bench_function("inverse_loop_one_level", |b| {
        b.iter(|| {
            let level = detect_level(&topo, 1).expect("subdivided");
            exact_inverse_operator(&topo, &level).apply(&mesh.positions)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
