//! An evaluator of one Loop limit surface for one control set: what foot-point searches
//! and tessellations call millions of times. Basis rows cost a 12 x 15 stencil product per
//! column and a column per support point; positions through Bezier ordinates cost one
//! de Casteljau run.

use super::patch::{evaluate_patch, Jac};
use super::{clamp_param, FacePatch, LoopLimitSurface};
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use std::cell::RefCell;
use std::sync::atomic::{AtomicU64, Ordering};

/// Source of evaluator ids: a leaf memo entry is only valid for the evaluator (control
/// set) that wrote it, and ids are never reused, unlike addresses.
static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// The irregular-face leaves each thread evaluated last: evaluator id, the leaf patch's
/// address and the face (faces of one 1-ring shape share their leaves, each over its own
/// controls), its ordinates and base. The Newton steps of one point, and the data points
/// near it (the fit's data are in spatial order), mostly land in leaves evaluated just
/// before, whose ordinates then cost nothing. A single entry missed whenever a point's
/// steps crossed between leaves of different depths near an irregular corner. With 256
/// entries, a quarter of bun_zipper's 1.8M leaf evaluations per fit still miss: those are
/// first visits of their leaf for that control set (2048 entries saved 2 % of them).
type LeafMemo = (u64, (usize, usize), [DVec3; 15], DVec3);

/// Entries of each thread's leaf memo, direct-mapped by the leaf's address and face.
const LEAF_MEMO_SLOTS: usize = 256;

const EMPTY_LEAF: LeafMemo = (0, (0, 0), [DVec3::ZERO; 15], DVec3::ZERO);

thread_local! {
    static LEAVES: RefCell<Box<[LeafMemo; LEAF_MEMO_SLOTS]>> =
        RefCell::new(Box::new([EMPTY_LEAF; LEAF_MEMO_SLOTS]));
}

/// The memo slot of a leaf: its patch's address (structures of at least 8 bytes) and face.
fn leaf_slot((patch, face): (usize, usize)) -> usize {
    let h = ((patch >> 3) ^ face.wrapping_mul(0x9E37_79B9)).wrapping_mul(0x85EB_CA6B);
    (h >> 8) % LEAF_MEMO_SLOTS
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
                    return LEAVES.with_borrow_mut(|leaves| {
                        let entry = &mut leaves[leaf_slot(key)];
                        if (entry.0, entry.1) != (self.id, key) {
                            let origin = self.controls[ip.support[0] as usize];
                            let (ords, base) = rp.ordinates(|c| {
                                self.controls[ip.support[c as usize] as usize] - origin
                            });
                            *entry = (self.id, key, ords, base + origin);
                        }
                        evaluate_patch(&entry.2, entry.3, a, b, &jac)
                    });
                }
            }
        }
        self.surface.evaluate(self.controls, p)
    }
}
