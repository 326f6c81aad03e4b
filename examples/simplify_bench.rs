//! The control-mesh simplification alone (`mesh::simplify` with the whole-object fit's
//! default guards, `ObjectOptions::default().simplify`), best of RUNS, with a
//! fingerprint of its output (positions' bits, faces, every landing) so that a change
//! meant to be faster only can be checked to give the same mesh bit for bit.
//!
//!     cargo run --release --example simplify_bench [-- FILE [RUNS [SHARE_PCT]]]
//!
//! Defaults: `../shared/data/models/bun_zipper.ply`, 5 runs, 3 % of the vertices (the
//! simplification's share of a 5 % budget when refinement spends the rest). The mesh is
//! cleaned and renumbered as the object fit takes it (`fitted_component`). Then the data's
//! RMS and largest distance to the simplified mesh and to where each point landed on it.

use std::hash::{Hash, Hasher};
use std::path::PathBuf;
use std::time::Instant;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::clean::CleanOptions;
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::simplify::{simplify, SimplifyOptions};
use trispline::pipeline::object::{fitted_component, ObjectOptions};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let mut args = std::env::args().skip(1);
    let file = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared/data/models/bun_zipper.ply"));
    let runs: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(5);
    let share: f64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(3.0);
    let mesh = read_mesh_file(&file, &LoadOptions::default())?.mesh;
    let component = fitted_component(&mesh, &CleanOptions::default())
        .ok_or("cleaning left no manifold component")?;
    let n = component.positions.len();
    let opts = SimplifyOptions {
        target_vertices: ((share / 100.0) * n as f64).round() as usize,
        ..ObjectOptions::default().simplify
    };
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        let simplified = simplify(&component, &opts)?;
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
        last = Some(simplified);
    }
    let simplified = last.ok_or("no run")?;
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    for p in &simplified.mesh.positions {
        p.to_array().map(f64::to_bits).hash(&mut hasher);
    }
    simplified.mesh.triangles.hash(&mut hasher);
    for l in &simplified.landing {
        (l.face, l.u.to_bits(), l.v.to_bits()).hash(&mut hasher);
    }
    println!(
        "{}: {n} vertices -> {} ({} collapses), best of {runs}: {best:.1} ms, fingerprint {:016x}",
        file.display(),
        simplified.mesh.positions.len(),
        simplified.collapses,
        hasher.finish()
    );
    // How well the mesh and the landings (the fit's first parameters) stand for the data.
    let query = MeshDistance::new(&simplified.mesh);
    let rms = |d: &[f64]| (d.iter().map(|x| x * x).sum::<f64>() / d.len().max(1) as f64).sqrt();
    let to_mesh: Vec<f64> = component
        .positions
        .iter()
        .filter_map(|p| query.distance(*p))
        .collect();
    let to_landing: Vec<f64> = component
        .positions
        .iter()
        .zip(&simplified.landing)
        .filter_map(|(p, l)| Some(l.position_on(&simplified.mesh)?.distance(*p)))
        .collect();
    println!(
        "data to the mesh: RMS {:.4e}, max {:.4e}; data to its landing: RMS {:.4e}, max {:.4e}",
        rms(&to_mesh),
        to_mesh.iter().copied().fold(0.0, f64::max),
        rms(&to_landing),
        to_landing.iter().copied().fold(0.0, f64::max)
    );
    Ok(())
}
