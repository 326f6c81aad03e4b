//! What the collapse loop keeps of a vertex, in one record.

use super::quadric::Quadric;
use glam::DVec3;
use smallvec::SmallVec;

/// A vertex of the mesh being collapsed. Every candidate collapse reads all of this for
/// both ends of its edge, and the ends are anywhere in memory: held as six arrays, an end
/// cost up to six cache misses; one record aligned to a cache line is two lines, and the
/// staleness check of a queue entry (`alive`, `version`) reads only the first.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub(super) struct Vertex {
    pub pos: DVec3,
    /// Bumped by every collapse into or of the vertex (queue entries of older versions are
    /// stale).
    pub version: u32,
    pub alive: bool,
    /// Stays in place: a corner, or kept by the caller.
    pub locked: bool,
    /// Takes part in no collapse at all, not even as the end that stays (`halves`: a
    /// vertex the other half shares).
    pub frozen: bool,
    pub boundary: bool,
    pub quadric: Quadric,
}

impl Vertex {
    pub(super) fn new(pos: DVec3, boundary: bool) -> Self {
        Self {
            pos,
            version: 0,
            alive: true,
            locked: false,
            frozen: false,
            boundary,
            quadric: Quadric::default(),
        }
    }
}

/// A vertex's live faces. Inline up to 10 (the valence guard keeps nearly every vertex
/// at 12 faces or fewer, most near 6): the collapses walk the face lists of the two ends
/// and their neighbours, and separately allocated lists were a cache miss each.
pub(super) type FaceList = SmallVec<[u32; 10]>;
