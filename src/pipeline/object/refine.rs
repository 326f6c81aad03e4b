//! Adaptive refinement of a fitted object's control mesh (Marinov & Kobbelt 2005's local
//! refinement): while data points stay beyond the tolerance on more than a few faces, the
//! longest edge of as many control faces as hold such points, those with the largest
//! squared error, is split, the valences are tidied by flips, and the surface is fitted
//! again on the refined mesh, until the control budget is spent, no point is beyond the
//! tolerance, or the rounds run out.
//!
//! The misfit says how much to refine, the squared error where: measured on bun_zipper
//! (5 % controls, 250 um tolerance, 8 rounds), splitting only faces with points beyond the
//! tolerance left the RMS at 66 um against 62 um and did not lower the max (717 um both),
//! which comes from a few spikes of the data.
//!
//! The refined net is laid out at the fitted surface's limit positions (each control
//! vertex's limit point, each new vertex at the limit point of its edge's midpoint): that
//! piecewise-linear mesh interpolates the fitted surface, so the data points of changed
//! faces land on it by projection as they did on the simplification, and the points of
//! unchanged faces keep their foot points exactly.

use super::layout::{edge_key, LayoutOptions, Net};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rustc_hash::FxHashSet;

/// Refinement settings.
#[derive(Clone, Debug)]
pub struct RefineOptions {
    /// Refinement rounds at most; 0 fits the simplification at the whole budget.
    pub rounds: usize,
    /// Share of the control budget the simplification keeps when refinement is on; the
    /// rest is spent by the rounds where the error is.
    pub start_share: f64,
    /// Distance beyond which a data point misses the budget: a round splits as many
    /// control faces as hold such points (those with the most squared error), and none
    /// runs while they are fewer than one per 100 controls. `None`: every point off the
    /// surface counts, so each round spends its share of the budget.
    pub tolerance: Option<f64>,
    /// Foot-point rounds of the fits between refinements, which only show where to refine
    /// next (the last fit runs all of `ObjectOptions::rounds`).
    pub intermediate_rounds: usize,
    /// Start each refit from the previous fit's controls (`Refined::warm`) instead of a
    /// point fit at the refined mesh's landings. Off: measured (object_table, 5 %
    /// controls) it saved only 3-6 % of the CPU time and left bun_zipper at 65.5 um
    /// against 63.8, fertility 7 % and decimated-max 11 % worse (camelhead 5 % better).
    pub warm: bool,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            rounds: 3,
            start_share: 0.6,
            tolerance: None,
            intermediate_rounds: 2,
            warm: false,
        }
    }
}

/// One refinement stage: the fit it ended with.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct RefineRound {
    /// Control points of the fit.
    pub controls: usize,
    /// Its RMS distance.
    pub rms: f64,
    /// Its largest distance.
    pub max: f64,
    /// Data points beyond the tolerance (all points with distance > 0 without one).
    pub beyond: usize,
    /// Whether the round split faces where the surface strayed from the data (beyond the
    /// budget) rather than where the data's error was.
    pub stray_repair: bool,
}

impl RefineRound {
    /// The round's figures from a fit's controls and distances.
    pub(super) fn of(
        controls: usize,
        rms: f64,
        max: f64,
        distances: &[f64],
        tolerance: Option<f64>,
    ) -> Self {
        let tol = tolerance.unwrap_or(0.0);
        Self {
            controls,
            rms,
            max,
            beyond: distances.iter().filter(|&&d| d > tol).count(),
            stray_repair: false,
        }
    }
}

/// A refinement round needs at least one control face with points beyond the tolerance,
/// and one edge to split, per this many controls. A round is a whole refit, and points
/// beyond the tolerance on so few faces are isolated (outliers, noise spikes) rather than
/// shape the control mesh misses: on bun_zipper subdivided once (139k points, 250 um
/// tolerance) three rounds for one or two such points each took 3.8 of the 7.4 s, and the
/// max moved 257 -> 285 -> 314 -> 270 um.
pub(super) const MIN_FACES_BEYOND_SHARE: usize = 100;

/// What refinement reads of a fit.
pub(super) struct Fitted<'a> {
    /// The data mesh.
    pub component: &'a TriMesh,
    /// The fitted surface.
    pub surface: &'a LoopLimitSurface,
    /// Its control points.
    pub controls: &'a [DVec3],
    /// Each data point's foot point ...
    pub params: &'a [SurfaceParam],
    /// ... and distance.
    pub distances: &'a [f64],
}

/// A refined control mesh, ready to be fitted.
pub(super) struct Refined {
    /// The control mesh at the interpolating net's positions.
    pub mesh: TriMesh,
    /// Each data point's landing on it.
    pub params: Vec<SurfaceParam>,
    /// Its crease edges.
    pub creases: Vec<[u32; 2]>,
    /// Control positions a warm refit starts from (`RefineOptions::warm`): the fitted
    /// controls, and each new vertex by Loop's edge rule from the controls around its edge
    /// (away from the splits the surface is the fitted one).
    pub warm: Vec<DVec3>,
}

/// Control faces holding a data point farther than `tolerance` from the surface (every
/// face with a point off it without one).
pub(super) fn faces_beyond(fit: &Fitted, tolerance: Option<f64>) -> usize {
    faces_holding_beyond(fit, tolerance.unwrap_or(0.0))
        .iter()
        .filter(|&&b| b)
        .count()
}

/// Per control face of `fit`, whether it holds a data point farther than `tolerance` from
/// the surface.
pub(super) fn faces_holding_beyond(fit: &Fitted, tolerance: f64) -> Vec<bool> {
    let mut beyond = vec![false; fit.surface.domain_face_count()];
    for (p, &d) in fit.params.iter().zip(fit.distances) {
        if d > tolerance {
            if let Some(b) = beyond.get_mut(p.face as usize) {
                *b = true;
            }
        }
    }
    beyond
}

/// Each control vertex's limit point on the surface of `controls` (the control itself for
/// a vertex no face holds): the net through these interpolates the surface.
pub(super) fn limit_positions(surface: &LoopLimitSurface, controls: &[DVec3]) -> Vec<DVec3> {
    let evaluate = surface.evaluator(controls);
    let corner = |f: usize, k: usize| {
        let (u, v) = match k {
            0 => (1.0, 0.0),
            1 => (0.0, 1.0),
            _ => (0.0, 0.0),
        };
        SurfaceParam {
            face: f as u32,
            u,
            v,
        }
    };
    let mut limit: Vec<Option<DVec3>> = vec![None; controls.len()];
    for (f, t) in surface.faces().iter().enumerate() {
        for (k, &v) in t.iter().enumerate() {
            if limit[v as usize].is_none() {
                limit[v as usize] = Some(evaluate(corner(f, k)).position);
            }
        }
    }
    limit
        .iter()
        .zip(controls)
        .map(|(l, c)| l.unwrap_or(*c))
        .collect()
}

/// Which control faces a refinement splits, and in which order.
#[derive(Clone, Copy)]
pub(super) enum Splits<'a> {
    /// Every face with data error, the largest squared error first.
    ByError,
    /// The faces marked, with data error, the largest squared error first.
    Marked(&'a [bool]),
    /// The faces with a positive rank, data on them or not, the highest rank first.
    Ranked(&'a [f64]),
}

/// The control mesh of `fit` with up to `add` edges split on the faces `splits` picks
/// (see the module docs) and each data point's landing on it; `None` when no face is
/// picked or the net cannot be built.
pub(super) fn refined_mesh(
    fit: &Fitted,
    add: usize,
    layout: &LayoutOptions,
    splits: Splits,
) -> Option<Refined> {
    let faces = fit.surface.faces();
    let evaluate = fit.surface.evaluator(fit.controls);
    let limit = limit_positions(fit.surface, fit.controls);

    let mut error = vec![0.0; faces.len()];
    for (p, &d) in fit.params.iter().zip(fit.distances) {
        if let Some(e) = error.get_mut(p.face as usize) {
            *e += d * d;
        }
    }
    let rank = match splits {
        Splits::Ranked(rank) => rank,
        _ => &error,
    };
    let picked = |f: usize| match splits {
        Splits::ByError => error[f] > 0.0,
        Splits::Marked(marks) => error[f] > 0.0 && marks.get(f) == Some(&true),
        Splits::Ranked(rank) => rank.get(f).is_some_and(|&r| r > 0.0),
    };
    let mut worst: Vec<usize> = (0..faces.len()).filter(|&f| picked(f)).collect();
    if worst.is_empty() {
        return None;
    }
    worst.sort_by(|&a, &b| rank[b].total_cmp(&rank[a]).then(a.cmp(&b)));
    let control = TriMesh::new(limit.clone(), faces.to_vec());
    let mut net = Net::new(
        fit.component,
        control,
        fit.params,
        fit.surface.crease_edges(),
    )?;
    net.keep_corners();
    // The longest edge of each worst face (by the interpolating net) is split at the limit
    // point of its midpoint, each edge once; where a corner is opposite it (the split
    // would give the corner a second face), the next longest.
    let mut added = 0;
    let mut warm = fit.controls.to_vec();
    for f in worst {
        if added >= add {
            break;
        }
        let t = faces[f];
        let len = |k: usize| limit[t[k] as usize].distance(limit[t[(k + 1) % 3] as usize]);
        let mut order = [0, 1, 2];
        order.sort_by(|&i, &j| len(j).total_cmp(&len(i)));
        for k in order {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if !net.has_edge(a, b) {
                // Split already from a neighbouring face.
                break;
            }
            let mut w = [0.0; 3];
            w[k] = 0.5;
            w[(k + 1) % 3] = 0.5;
            let mid = evaluate(SurfaceParam {
                face: f as u32,
                u: w[0],
                v: w[1],
            })
            .position;
            let warm_at = edge_rule(&net, &warm, a, b);
            if net.split_edge(a, b, mid) {
                warm.push(warm_at);
                added += 1;
                break;
            }
        }
    }
    // Flips only: relaxing would move the vertices just placed where the error is.
    net.tidy(&LayoutOptions {
        relax_steps: 0,
        rounds: 1,
        ..layout.clone()
    });
    let (mesh, params, creases) = net.finish();
    Some(Refined {
        mesh,
        params,
        creases,
        warm,
    })
}

/// Per face of `refined`, whether `previous` lacks it (the faces a refinement made), by
/// their corners in any order.
pub(super) fn new_faces(previous: &LoopLimitSurface, refined: &LoopLimitSurface) -> Vec<bool> {
    let sorted = |f: &[u32; 3]| {
        let mut f = *f;
        f.sort_unstable();
        f
    };
    let old: FxHashSet<[u32; 3]> = previous.faces().iter().map(sorted).collect();
    refined
        .faces()
        .iter()
        .map(|f| !old.contains(&sorted(f)))
        .collect()
}

/// Loop's odd (edge) rule for edge (a, b) of `net` at the positions `at`: 3/8 of each end
/// and 1/8 of each opposite corner inside, the midpoint on a boundary or crease edge.
fn edge_rule(net: &Net, at: &[DVec3], a: u32, b: u32) -> DVec3 {
    let mid = 0.5 * (at[a as usize] + at[b as usize]);
    if net.creases.contains(&edge_key(a, b)) {
        return mid;
    }
    let opposite: Vec<u32> = net.vfaces[a as usize]
        .iter()
        .map(|&f| net.faces[f as usize])
        .filter(|t| t.contains(&b))
        .filter_map(|t| t.iter().copied().find(|&c| c != a && c != b))
        .collect();
    match opposite[..] {
        [c, d] => 0.75 * mid + 0.125 * (at[c as usize] + at[d as usize]),
        _ => mid,
    }
}
