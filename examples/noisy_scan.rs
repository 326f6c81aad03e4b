//! Writes the large closed-scan benchmark input of the whole-object issue: Stanford's
//! bun_zipper Loop-subdivided once (about 139k vertices, its 5 holes kept) with 40 um of
//! Gaussian noise along the vertex normals, the noise of a structured-light scanner. The
//! noise is seeded, so every run writes the same file.
//!
//!     cargo run --release --example noisy_scan -- /tmp/noisy_bunny.ply [SOURCE]
//!     cargo run --release --example cold_fit -- /tmp/noisy_bunny.ply 5
//!
//! SOURCE defaults to `../shared/data/models/bun_zipper.ply`.

use std::path::PathBuf;
use trispline::io::writers::ply_bytes;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::loop_subdiv::subdivide;
use trispline::TriMesh;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

const NOISE_SIGMA_M: f64 = 40e-6;

/// xorshift64 uniforms in (0, 1], turned Gaussian by Box-Muller: no crate needed for a
/// benchmark input, and the sequence is fixed across platforms.
struct Gaussian(u64);

impl Gaussian {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }

    fn sample(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

fn main() -> Res<()> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().ok_or("usage: noisy_scan OUT.ply [SOURCE]")?);
    let source = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared/data/models/bun_zipper.ply"));
    let mesh = read_mesh_file(&source, &LoadOptions::default())?.mesh;
    let fine = subdivide(&mesh, 1)?;
    let normals = fine.vertex_normals();
    let mut noise = Gaussian(0x9e37_79b9_7f4a_7c15);
    let positions = fine
        .positions
        .iter()
        .zip(&normals)
        .map(|(p, n)| *p + *n * (NOISE_SIGMA_M * noise.sample()))
        .collect();
    let noisy = TriMesh::new(positions, fine.triangles);
    std::fs::write(&out, ply_bytes(&noisy))?;
    println!(
        "{}: {} vertices, {} faces, noise sigma {} um",
        out.display(),
        noisy.positions.len(),
        noisy.triangles.len(),
        NOISE_SIGMA_M * 1e6
    );
    Ok(())
}
