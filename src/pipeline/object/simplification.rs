//! The control mesh's simplification, with or without its triangle-quality guard.
//!
//! The guard (`SimplifyOptions::min_quality`) refuses collapses that leave thin faces,
//! because a Loop limit surface over an even mesh fits better. On a part with crease
//! chains that preference can cost the mesh its shape: collapses run along a chain only,
//! the faces beside a machined edge are long and thin, so the guard refuses most of them,
//! and the simplification reaches its count through costly collapses across curved faces
//! instead, or stops above it. Measured on CGAL's meshes at their first (60 %) target:
//! turbine's guarded mesh stood 7.4e-3 RMS from its data against 4.3e-3 unguarded,
//! rotor_small's 1.29e-2 against 6.0e-3, and couplingdown's and blade's stalled at 448
//! and 693 vertices for budgets of 55 and 247 (unguarded: 147 and 247); on fandisk,
//! anchor_dense and cheese the two were within 15 %. So on data with creases both are
//! simplified, and the guard gives way when it costs that much: the fit starts from the
//! mesh that holds the shape. Data without creases (scans, organic models) is simplified
//! once, with the guard, as before. Data whose crease vertices are fewer than
//! `FEW_CREASES_SHARE` of the target is simplified with the guard first, and without it
//! only when the guarded mesh stops above the target: the chain collapses the guard
//! refuses, which would spend the budget across curved faces instead, are no more than
//! the crease vertices, so where it reaches the target it is trusted as on data without
//! creases. A stall is not bounded so: sharp edges the crease detection left unmarked
//! stall the guard too (a faceted prism with 8 of its crease edges marked stopped at 978
//! vertices for a target of 200). The scans' few spurious crease edges so no longer pay
//! for a second simplification: bun_zipper subdivided once (139k vertices, 5 crease edges)
//! took 1.0-1.1 s to simplify twice side by side and takes 0.57-0.76 s once (the same
//! control mesh).

use crate::mesh::simplify::{
    simplify_with_creases, simplify_with_topology, Simplified, SimplifyError, SimplifyOptions,
};
use crate::mesh::topology::Topology;
use crate::TriMesh;

/// The guarded mesh is kept unless its data vertices stand this many times as far (RMS)
/// from it as from the unguarded one: the guard's evenness is worth a little accuracy
/// (on the shared organic models it costs under 5 %), not a large share of it.
const GUARD_COST_LIMIT: f64 = 1.5;

/// Crease vertices below this share of the target vertices: the unguarded mesh is made
/// only where the guarded one stalls (module docs).
const FEW_CREASES_SHARE: f64 = 0.05;

/// Whether `creases` touch fewer than `FEW_CREASES_SHARE` of `target` vertices.
fn few_creases(creases: &[[u32; 2]], target: usize) -> bool {
    let mut vertices: Vec<u32> = creases.iter().flatten().copied().collect();
    vertices.sort_unstable();
    vertices.dedup();
    (vertices.len() as f64) < FEW_CREASES_SHARE * target as f64
}

/// `component` simplified for a control mesh (`opts`, keeping `creases`), and whether
/// the triangle-quality guard was dropped (module docs); `topo` is the component's
/// topology when the caller has it.
pub(super) fn simplify_for_control(
    component: &TriMesh,
    topo: Option<&Topology>,
    opts: &SimplifyOptions,
    creases: &[[u32; 2]],
) -> Result<(Simplified, bool), SimplifyError> {
    let simplify = |opts: &SimplifyOptions| match topo {
        Some(topo) => simplify_with_topology(component, topo, opts, creases),
        None => simplify_with_creases(component, opts, creases),
    };
    if creases.is_empty() || opts.min_quality <= 0.0 {
        return Ok((simplify(opts)?, false));
    }
    let unguarded_opts = SimplifyOptions {
        min_quality: 0.0,
        ..opts.clone()
    };
    let (guarded, unguarded) = if few_creases(creases, opts.target_vertices) {
        let guarded = simplify(opts)?;
        if guarded.mesh.positions.len() <= opts.target_vertices {
            return Ok((guarded, false));
        }
        (guarded, simplify(&unguarded_opts))
    } else {
        // Each simplification is sequential but for its landing carrier: side by side
        // they take about the time of one.
        let (guarded, unguarded) = rayon::join(|| simplify(opts), || simplify(&unguarded_opts));
        (guarded?, unguarded)
    };
    let Ok(unguarded) = unguarded else {
        return Ok((guarded, false));
    };
    let judged = |s: &Simplified| Judged {
        vertices: s.mesh.positions.len(),
        rms: landing_rms(component, s),
    };
    let noise = ROUNDING_SHARE * component.bounds_diagonal();
    if guard_gives_way(
        judged(&guarded),
        judged(&unguarded),
        opts.target_vertices,
        noise,
    ) {
        Ok((unguarded, true))
    } else {
        Ok((guarded, false))
    }
}

/// A simplification's size and the RMS distance of the data to it.
#[derive(Clone, Copy, Debug)]
struct Judged {
    vertices: usize,
    rms: f64,
}

/// Distances below this share of the data's diagonal are rounding, not shape: two exact
/// meshes of a faceted part differ there by chance.
const ROUNDING_SHARE: f64 = 1e-9;

/// Whether the guard gives way: when it stops the simplification above the `target`
/// where the unguarded one goes further (it costs the user controls) without the data
/// standing more than `GUARD_COST_LIMIT` times as far from it, or when the data stand more
/// than that many times as far from the guarded mesh; distances below `noise` are equal.
fn guard_gives_way(guarded: Judged, unguarded: Judged, target: usize, noise: f64) -> bool {
    let stalled = guarded.vertices > target
        && unguarded.vertices < guarded.vertices
        && unguarded.rms <= (GUARD_COST_LIMIT * guarded.rms).max(noise);
    let costly = guarded.rms > noise && guarded.rms > GUARD_COST_LIMIT * unguarded.rms;
    stalled || costly
}

/// RMS distance of the data vertices to where they landed on the simplified mesh.
fn landing_rms(component: &TriMesh, simplified: &Simplified) -> f64 {
    let mesh = &simplified.mesh;
    let mut sum = 0.0;
    let mut count = 0usize;
    for (p, l) in component.positions.iter().zip(&simplified.landing) {
        let Some(on) = l.position_on(mesh) else {
            continue;
        };
        sum += p.distance_squared(on);
        count += 1;
    }
    if count == 0 {
        return f64::INFINITY;
    }
    (sum / count as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata::faceted_prism as prism;

    fn options(target: usize) -> SimplifyOptions {
        SimplifyOptions {
            target_vertices: target,
            isotropy: 1e-3,
            ..Default::default()
        }
    }

    /// A faceted part whose sides need long thin faces: the guard stops the
    /// simplification far above the budget, so it gives way, and the unguarded mesh holds
    /// the part exactly at the budget.
    #[test]
    fn a_guard_that_stalls_above_the_budget_gives_way() {
        let (mesh, creases) = prism(8, 60, 2);
        let opts = options(40);
        let guarded = simplify_with_creases(&mesh, &opts, &creases).expect("simplified");
        let topo = Topology::from_mesh(&mesh).expect("manifold");
        let (chosen, dropped) =
            simplify_for_control(&mesh, Some(&topo), &opts, &creases).expect("simplified");
        let (gn, cn) = (guarded.mesh.positions.len(), chosen.mesh.positions.len());
        assert!(gn > 40, "the guarded mesh reached the budget ({gn})");
        assert!(dropped, "the guard kept at {gn} vertices");
        assert!(cn < gn, "{cn} against {gn} vertices");
        let rms = landing_rms(&mesh, &chosen);
        assert!(
            rms < 1e-9,
            "the unguarded mesh is off the prism by {rms:.3e}"
        );
    }

    /// Two exact meshes of the same facets differ by rounding only: the guard stays.
    #[test]
    fn exact_meshes_keep_the_guard() {
        let (mesh, creases) = prism(8, 12, 12);
        let (_, dropped) =
            simplify_for_control(&mesh, None, &options(40), &creases).expect("simplified");
        assert!(!dropped);
    }

    /// The rule itself: the cost of the guard in accuracy, beyond rounding, or in size.
    #[test]
    fn the_guard_gives_way_to_a_large_cost_only() {
        let at = |vertices, rms| Judged { vertices, rms };
        let noise = 1e-12;
        assert!(guard_gives_way(at(100, 2e-3), at(100, 1e-3), 100, noise));
        assert!(!guard_gives_way(at(100, 1.4e-3), at(100, 1e-3), 100, noise));
        assert!(!guard_gives_way(at(100, 3e-13), at(100, 1e-13), 100, noise));
        assert!(guard_gives_way(at(450, 1e-3), at(150, 1.4e-3), 100, noise));
        assert!(!guard_gives_way(at(450, 1e-3), at(150, 3e-3), 100, noise));
        assert!(guard_gives_way(at(450, 0.0), at(100, 1e-13), 100, noise));
        assert!(!guard_gives_way(at(100, 1e-3), at(90, 1e-3), 100, noise));
        assert!(!guard_gives_way(at(450, 1e-3), at(450, 1e-3), 100, noise));
    }

    /// Without creases the guarded simplification is the only one run and is kept.
    #[test]
    fn without_creases_the_guard_stays() {
        let (mesh, _) = prism(8, 24, 6);
        let opts = options(40);
        let (chosen, dropped) = simplify_for_control(&mesh, None, &opts, &[]).expect("simplified");
        let guarded = simplify_with_creases(&mesh, &opts, &[]).expect("simplified");
        assert!(!dropped);
        assert_eq!(chosen.mesh.positions, guarded.mesh.positions);
        assert_eq!(chosen.mesh.triangles, guarded.mesh.triangles);
    }

    /// With few crease vertices the guarded mesh is kept where it reaches the target (a
    /// torus with a short crease run); where it stalls above it (a prism with 8 of its
    /// crease edges marked: its unmarked sharp edges stall the guard too) the unguarded
    /// one is simplified and judged as with many.
    #[test]
    fn with_few_crease_vertices_the_guard_is_judged_only_where_it_stalls() {
        let target = 200;
        let opts = options(target);
        let torus = crate::testdata::torus(40, 20);
        let run: Vec<[u32; 2]> = (0..6u32).map(|i| [20 * i, 20 * (i + 1)]).collect();
        let (prism, prism_creases) = prism(8, 60, 2);
        let mut marked = prism_creases.clone();
        marked.sort_by_key(|e| e[0].max(e[1]));
        marked.truncate(8);
        assert!(few_creases(&run, target) && few_creases(&marked, target));
        assert!(!few_creases(&prism_creases, target));

        let guarded = simplify_with_creases(&torus, &opts, &run).expect("simplified");
        let (chosen, dropped) =
            simplify_for_control(&torus, None, &opts, &run).expect("simplified");
        assert_eq!(guarded.mesh.positions.len(), target);
        assert!(!dropped);
        assert_eq!(chosen.mesh.positions, guarded.mesh.positions);
        assert_eq!(chosen.crease_edges.len(), guarded.crease_edges.len());

        let guarded = simplify_with_creases(&prism, &opts, &marked).expect("simplified");
        let (chosen, dropped) =
            simplify_for_control(&prism, None, &opts, &marked).expect("simplified");
        let n = guarded.mesh.positions.len();
        assert!(n > target, "the guarded prism reached the budget ({n})");
        assert!(dropped, "the guard kept {n} vertices");
        assert!(chosen.mesh.positions.len() < n);
    }
}
