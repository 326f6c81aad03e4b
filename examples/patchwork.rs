//! Measures `trispline export`'s patchwork of a mesh-layout Loop surface at each split
//! depth: patches, deviation from the limit surface and time.
//!
//! usage: cargo run --release --example patchwork -- SURFACE.json [MAX_DEPTH] [MAX_CORNER_LEVELS]

use std::time::Instant;
use trispline::bspline::loop_patches::{loop_patchwork, Split};
use trispline::io::surface_json::{read_surface_json, SurfaceDescription};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: patchwork SURFACE.json [MAX_DEPTH]"))?;
    let max_depth: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(2);
    let max_levels: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(0);
    let SurfaceDescription::LoopMesh { surface, controls } = read_surface_json(path.as_ref())?
    else {
        anyhow::bail!("{path}: not a mesh-layout Loop surface");
    };
    let (lo, hi) = controls
        .iter()
        .fold((controls[0], controls[0]), |(l, h), p| {
            (l.min(*p), h.max(*p))
        });
    let diagonal = (hi - lo).length();
    println!(
        "{path}: {} controls, {} faces ({} irregular), diagonal {diagonal:.4e}",
        controls.len(),
        surface.faces().len(),
        surface.irregular_face_count()
    );
    for (depth, corner_levels) in
        (0..=max_depth).flat_map(|d| (0..=max_levels).map(move |l| (d, l)))
    {
        let t = Instant::now();
        let p = loop_patchwork(
            &surface,
            &controls,
            Split {
                depth,
                corner_levels,
            },
        )?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let d = p.deviation;
        println!(
            "depth {depth} corner levels {corner_levels}: {} patches in {ms:.0} ms; deviation max {:.3e} ({:.2e} of diagonal) rms {:.3e}, normal p99 {:.2} max {:.2} deg over {} samples",
            p.patches.len(), d.max, d.max / diagonal, d.rms, d.normal_p99_deg, d.normal_max_deg, d.samples
        );
    }
    Ok(())
}
