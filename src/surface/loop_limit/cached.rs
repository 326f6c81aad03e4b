//! An evaluator of one Loop limit surface for one control set: what foot-point searches
//! and tessellations call millions of times. Basis rows cost a 12 x 15 stencil product per
//! column and a column per support point; positions through Bezier ordinates cost one
//! de Casteljau run.

use super::patch::{evaluate_patch, Jac};
use super::{clamp_param, FacePatch, LoopLimitSurface};
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

/// Source of evaluator ids: a leaf memo entry is only valid for the evaluator (control
/// set) that wrote it, and ids are never reused, unlike addresses.
static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// The last irregular-face leaf each thread evaluated: evaluator id, the leaf patch's
/// address and the face (faces of one 1-ring shape share their leaves, each over its own
/// controls), its ordinates and base. Consecutive evaluations (Newton steps of one point,
/// neighbouring data points) mostly land in the same leaf, whose ordinates then cost
/// nothing.
type LeafMemo = (u64, (usize, usize), [DVec3; 15], DVec3);

thread_local! {
    static LAST_LEAF: Cell<LeafMemo> = const { Cell::new((0, (0, 0), [DVec3::ZERO; 15], DVec3::ZERO)) };
}

pub(super) struct CachedEvaluator<'a> {
    id: u64,
    surface: &'a LoopLimitSurface,
    controls: &'a [DVec3],
    /// Bezier ordinates of each regular face (`None` for irregular faces).
    regular: Vec<Option<[DVec3; 15]>>,
}

impl<'a> CachedEvaluator<'a> {
    pub(super) fn new(surface: &'a LoopLimitSurface, controls: &'a [DVec3]) -> Self {
        let complete = controls.len() >= surface.control_count;
        let regular = surface
            .patches
            .iter()
            .map(|patch| match patch {
                // Too few controls: left to `evaluate`, which reports it as it always did.
                FacePatch::Regular(rp) if complete => {
                    Some(rp.ordinates(|c| controls[c as usize]).0)
                }
                _ => None,
            })
            .collect();
        Self {
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            surface,
            controls,
            regular,
        }
    }

    pub(super) fn evaluate(&self, p: SurfaceParam) -> Derivatives {
        let f = (p.face as usize).min(self.surface.patches.len() - 1);
        let (u, v) = clamp_param(p.u, p.v);
        if let Some(ords) = &self.regular[f] {
            return evaluate_patch(ords, DVec3::ZERO, u, v, &Jac::ID);
        }
        if let FacePatch::Irregular(ip) = &self.surface.patches[f] {
            if self.controls.len() >= self.surface.control_count {
                if let Some((rp, a, b, jac)) = ip.leaf(u, v) {
                    // Relative to a corner of the face: the leaf's stencil differences
                    // are scaled by 2^depth in the derivatives, so their rounding must
                    // be that of the local geometry, not of the coordinates' magnitude
                    // (the rows get the same from `restore_sums`).
                    let key = (rp as *const _ as usize, f);
                    let (id, at, mut ords, mut base) = LAST_LEAF.get();
                    if (id, at) != (self.id, key) {
                        let origin = self.controls[ip.support[0] as usize];
                        (ords, base) = rp
                            .ordinates(|c| self.controls[ip.support[c as usize] as usize] - origin);
                        base += origin;
                        LAST_LEAF.set((self.id, key, ords, base));
                    }
                    return evaluate_patch(&ords, base, a, b, &jac);
                }
            }
        }
        self.surface.evaluate(self.controls, p)
    }
}
