//! The one surface an input becomes: the largest component of the cleaned mesh, made
//! orientable where cleaning could not (a non-orientable strip keeps edges that two faces
//! run the same way: one of those faces goes, and the rest is cleaned again).

use crate::mesh::clean::{clean, CleanOptions, CleanReport};
use crate::mesh::spatial_order::spatially_ordered;
use crate::mesh::topology::Topology;
use crate::TriMesh;
use rustc_hash::FxHashSet;
use std::time::Instant;

/// Repair passes before the input is given up as not manifold.
const REPAIR_PASSES: usize = 8;

/// What the object path fits of an input, prepared once: the worker judges from it whether
/// an input goes the object path (`worker::object::object_reason`) and the fit starts
/// from it, where each cleaned the input on its own before (on a 139k-vertex closed scan
/// the second cleaning and topology took about 100 ms of a 3 s fit).
pub struct ObjectInput {
    /// The largest component (`largest_component`), in spatial order.
    pub mesh: TriMesh,
    /// What the first cleaning pass changed.
    pub cleaning: CleanReport,
    /// The cleaned input's other components, left out of the fit: their vertex counts,
    /// largest first ...
    pub left_out: Vec<usize>,
    /// ... of this many vertices in all the cleaned input's components.
    pub cleaned_vertices: usize,
    /// Its topology; `None` where the repairs left it no manifold.
    pub topology: Option<Topology>,
    /// Time taken to prepare it, in milliseconds.
    pub prepare_ms: f64,
}

impl ObjectInput {
    /// `mesh` prepared for the object path; `None` when cleaning leaves nothing.
    pub fn of(mesh: &TriMesh, opts: &CleanOptions) -> Option<Self> {
        let start = Instant::now();
        let (mesh, cleaning, parts, topology) = largest_component(mesh, opts)?;
        Some(Self {
            mesh,
            cleaning,
            left_out: parts.left_out,
            cleaned_vertices: parts.vertices,
            topology,
            prepare_ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }
}

/// The cleaned input's components besides the one fitted.
pub(super) struct OtherParts {
    /// Their vertex counts, largest first.
    pub left_out: Vec<usize>,
    /// Vertices of all components, the fitted one's included.
    pub vertices: usize,
}

/// The largest manifold, oriented component of `mesh` (see the module comment), its
/// vertices and faces in spatial order (`spatially_ordered`: the stages after walk it
/// faster, and the fit does not depend on the file's order), what the first cleaning
/// pass changed, the components it left out, and its topology (`None` where the repairs
/// left no manifold), or `None` if nothing is left. Pieces the repairs cut off a broken
/// component are not counted as left out: they were never components of their own.
pub(super) fn largest_component(
    mesh: &TriMesh,
    opts: &CleanOptions,
) -> Option<(TriMesh, CleanReport, OtherParts, Option<Topology>)> {
    let (mut part, report, others) = largest_cleaned(mesh, opts)?;
    // Whether a mesh is a manifold does not depend on its order: a component that is one
    // as cleaned has its topology built once, in the order the fit takes.
    let ordered = spatially_ordered(&part);
    if let Ok(topology) = Topology::from_mesh(&ordered) {
        return Some((ordered, report, others, Some(topology)));
    }
    for pass in 0..REPAIR_PASSES {
        // The first pass knows the answer from the ordered copy above.
        if pass > 0 && Topology::from_mesh(&part).is_ok() {
            break;
        }
        let kept = without_repeated_directed_edges(&part);
        if kept.triangles.len() == part.triangles.len() {
            break;
        }
        part = largest_cleaned(&kept, opts)?.0;
    }
    let ordered = spatially_ordered(&part);
    let topology = Topology::from_mesh(&ordered).ok();
    Some((ordered, report, others, topology))
}

/// Drops every face that runs a directed edge an earlier face already runs.
fn without_repeated_directed_edges(mesh: &TriMesh) -> TriMesh {
    let mut seen: FxHashSet<(u32, u32)> = FxHashSet::default();
    let mut triangles = Vec::with_capacity(mesh.triangles.len());
    for t in &mesh.triangles {
        let edges = [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])];
        if edges.iter().any(|e| seen.contains(e)) {
            continue;
        }
        for e in edges {
            seen.insert(e);
        }
        triangles.push(*t);
    }
    TriMesh::new(mesh.positions.clone(), triangles)
}

/// The cleaned mesh's largest edge-connected component (most faces; the lowest label on a
/// tie), its vertices in cleaned order, what cleaning changed and the other components.
fn largest_cleaned(
    mesh: &TriMesh,
    opts: &CleanOptions,
) -> Option<(TriMesh, CleanReport, OtherParts)> {
    let cleaned = clean(mesh, opts);
    let labels = &cleaned.face_component;
    let mut counts = vec![0usize; cleaned.mesh.triangles.len()];
    for &l in labels {
        counts[l as usize] += 1;
    }
    let (best, &size) = counts
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))?;
    if size == 0 {
        return None;
    }
    let others = other_parts(&cleaned.mesh, labels, best);
    let mut index = vec![u32::MAX; cleaned.mesh.positions.len()];
    let mut triangles = Vec::with_capacity(size);
    for (t, &l) in cleaned.mesh.triangles.iter().zip(labels) {
        if l as usize == best {
            for &v in t {
                index[v as usize] = 0;
            }
            triangles.push(*t);
        }
    }
    let mut positions = Vec::new();
    for (v, i) in index.iter_mut().enumerate() {
        if *i == 0 {
            *i = positions.len() as u32;
            positions.push(cleaned.mesh.positions[v]);
        }
    }
    for t in &mut triangles {
        *t = t.map(|v| index[v as usize]);
    }
    Some((TriMesh::new(positions, triangles), cleaned.report, others))
}

/// The vertex counts of the components of `mesh` (faces labelled by `labels`) other than
/// `kept`, and the vertices of all. Cleaning splits the vertices where components touch,
/// so each vertex is in one.
fn other_parts(mesh: &TriMesh, labels: &[u32], kept: usize) -> OtherParts {
    let mut label_of = vec![u32::MAX; mesh.positions.len()];
    let mut vertices = vec![0usize; mesh.triangles.len()];
    for (t, &l) in mesh.triangles.iter().zip(labels) {
        for &v in t {
            if label_of[v as usize] == u32::MAX {
                label_of[v as usize] = l;
                vertices[l as usize] += 1;
            }
        }
    }
    let all = vertices.iter().sum();
    let mut left_out: Vec<usize> = vertices
        .iter()
        .enumerate()
        .filter(|&(l, &n)| l != kept && n > 0)
        .map(|(_, &n)| n)
        .collect();
    left_out.sort_unstable_by(|a, b| b.cmp(a));
    OtherParts {
        left_out,
        vertices: all,
    }
}
