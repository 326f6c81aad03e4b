//! Splitting a cleaned scan into its edge-connected pieces and deciding which are worth a
//! surface of their own. Range scans come in 8–28 pieces, most of them a few stray triangles
//! at silhouettes; a fit of such a sliver is noise, so pieces are kept by size.

use crate::mesh::clean::Cleaned;
use crate::mesh::edge_table::EdgeTable;
use crate::mesh::stats::UnionFind;
use crate::pipeline::names::named;
use crate::TriMesh;
use glam::DVec3;
use rustc_hash::FxHashMap;

/// Which components of an input get a surface.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ComponentMode {
    /// The largest kept component only; the patch keeps its id.
    #[default]
    Largest,
    /// Every kept component, each as its own surface with the id suffixed `.c<k>`
    /// (k = 0 for the largest, in decreasing size).
    All,
}

named!(ComponentMode {
    Largest => "largest",
    All => "all",
});

/// Size thresholds: a component is kept when it has at least `min_vertices` vertices AND at
/// least `min_fraction` of the largest component's vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ComponentFilter {
    pub min_vertices: usize,
    pub min_fraction: f64,
}

/// One kept component: its own compacted mesh and where it sits (for matching the pieces
/// of a new version to those of the previous one).
#[derive(Clone, Debug)]
pub(crate) struct Component {
    pub mesh: TriMesh,
    pub centroid: DVec3,
    pub diagonal: f64,
}

#[derive(Clone, Debug, Default)]
pub(crate) struct Split {
    /// Kept components, largest first.
    pub kept: Vec<Component>,
    /// How many components the mesh has in all.
    pub total: usize,
    /// Vertex counts of the components dropped as too small, largest first.
    pub dropped_vertices: Vec<usize>,
}

/// Edge-connected components of `mesh`, each compacted, largest (by vertices) first; ties
/// go to the component whose first face comes first, so the order is deterministic.
pub fn connected_components(mesh: &TriMesh) -> Vec<TriMesh> {
    let mut uf = UnionFind::new(mesh.triangles.len());
    let edges = EdgeTable::new(&mesh.triangles, mesh.positions.len());
    for e in 0..edges.len() {
        let hs = edges.halves(e);
        for &g in &hs[1..] {
            uf.union(hs[0] as usize / 3, g as usize / 3);
        }
    }
    let root: Vec<usize> = (0..mesh.triangles.len()).map(|f| uf.find(f)).collect();
    split_by_label(mesh, |f| root[f])
}

/// `connected_components` of a cleaned mesh, from the components `clean` found.
pub fn cleaned_components(cleaned: &Cleaned) -> Vec<TriMesh> {
    let mesh = &cleaned.mesh;
    let labels = &cleaned.face_component;
    if labels.len() != mesh.triangles.len() || labels.iter().any(|&l| l as usize >= labels.len()) {
        return connected_components(mesh);
    }
    split_by_label(mesh, |f| labels[f] as usize)
}

/// The faces of `mesh` grouped by `label` (any face index of the group, one value per
/// group), each group compacted; the order of `connected_components`.
fn split_by_label(mesh: &TriMesh, label: impl Fn(usize) -> usize) -> Vec<TriMesh> {
    // Components numbered in first-face order and sized before they are filled (grown
    // push by push, the largest would be copied at every doubling).
    let mut slot_of_root = vec![u32::MAX; mesh.triangles.len()];
    let mut face_counts: Vec<usize> = Vec::new();
    for f in 0..mesh.triangles.len() {
        let root = label(f);
        if slot_of_root[root] == u32::MAX {
            slot_of_root[root] = face_counts.len() as u32;
            face_counts.push(0);
        }
        face_counts[slot_of_root[root] as usize] += 1;
    }
    let mut parts: Vec<TriMesh> = face_counts
        .iter()
        .map(|&faces| TriMesh {
            positions: Vec::with_capacity((3 * faces).min(mesh.positions.len())),
            triangles: Vec::with_capacity(faces),
        })
        .collect();
    // A vertex belongs to one component (faces sharing it are joined only through edges,
    // but a pinch vertex can sit in two): remember its index per (component, vertex).
    let mut local: FxHashMap<(usize, u32), u32> = FxHashMap::default();
    let mut single = vec![(u32::MAX, u32::MAX); mesh.positions.len()];
    for (f, t) in mesh.triangles.iter().enumerate() {
        let slot = slot_of_root[label(f)] as usize;
        let part = &mut parts[slot];
        let mut nt = [0u32; 3];
        for (k, &v) in t.iter().enumerate() {
            let (owner, id) = single[v as usize];
            nt[k] = if owner == slot as u32 {
                id
            } else if owner == u32::MAX {
                let id = part.positions.len() as u32;
                part.positions.push(mesh.positions[v as usize]);
                single[v as usize] = (slot as u32, id);
                id
            } else {
                *local.entry((slot, v)).or_insert_with(|| {
                    part.positions.push(mesh.positions[v as usize]);
                    (part.positions.len() - 1) as u32
                })
            };
        }
        part.triangles.push(nt);
    }
    // Stable sort: equal sizes keep first-face order.
    parts.sort_by_key(|p| std::cmp::Reverse(p.positions.len()));
    parts
}

/// Splits and filters. The largest component is always reported in `kept` when it passes
/// `min_vertices`; an empty `kept` means nothing is big enough.
/// `parts`: the components, largest first (`connected_components`, `cleaned_components`).
pub(crate) fn split_components(parts: Vec<TriMesh>, filter: &ComponentFilter) -> Split {
    let total = parts.len();
    let largest = parts.first().map_or(0, |p| p.positions.len());
    let mut split = Split {
        total,
        ..Split::default()
    };
    for part in parts {
        let n = part.positions.len();
        if n >= filter.min_vertices && n as f64 >= filter.min_fraction * largest as f64 {
            let centroid = part.positions.iter().sum::<DVec3>() / n.max(1) as f64;
            let diagonal = part.bounds_diagonal();
            split.kept.push(Component {
                mesh: part,
                centroid,
                diagonal,
            });
        } else {
            split.dropped_vertices.push(n);
        }
    }
    split
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` quads (2n triangles) starting at x = `x0`.
    fn strip(mesh: &mut TriMesh, x0: f64, n: usize) {
        let base = mesh.positions.len() as u32;
        for i in 0..=n {
            mesh.positions.push(DVec3::new(x0 + i as f64, 0.0, 0.0));
            mesh.positions.push(DVec3::new(x0 + i as f64, 1.0, 0.0));
        }
        for i in 0..n as u32 {
            let (a, b, c, d) = (
                base + 2 * i,
                base + 2 * i + 2,
                base + 2 * i + 1,
                base + 2 * i + 3,
            );
            mesh.triangles.push([a, b, c]);
            mesh.triangles.push([c, b, d]);
        }
    }

    #[test]
    fn components_come_largest_first_and_small_ones_are_dropped() {
        let mut mesh = TriMesh::default();
        strip(&mut mesh, 0.0, 3); // 8 vertices
        strip(&mut mesh, 10.0, 20); // 42 vertices
        strip(&mut mesh, 40.0, 9); // 20 vertices
        let all = connected_components(&mesh);
        let sizes: Vec<usize> = all.iter().map(|p| p.positions.len()).collect();
        assert_eq!(sizes, vec![42, 20, 8]);
        assert_eq!(all[0].triangles.len(), 40);

        let split = split_components(
            connected_components(&mesh),
            &ComponentFilter {
                min_vertices: 10,
                min_fraction: 0.4,
            },
        );
        assert_eq!(split.total, 3);
        let kept: Vec<usize> = split.kept.iter().map(|c| c.mesh.positions.len()).collect();
        assert_eq!(kept, vec![42, 20]);
        assert_eq!(split.dropped_vertices, vec![8]);
        // The second strip spans x = 40..49.
        assert!((split.kept[1].centroid.x - 44.5).abs() < 1e-12);

        let strict = split_components(
            connected_components(&mesh),
            &ComponentFilter {
                min_vertices: 10,
                min_fraction: 0.5,
            },
        );
        assert_eq!(strict.kept.len(), 1);
        assert_eq!(strict.dropped_vertices, vec![20, 8]);
    }

    /// The components `clean` finds while orienting are those of the edge table: the same
    /// pieces in the same order, also where cleaning split a non-manifold edge (a fin of
    /// three faces) and a pinch vertex (a triangle touching a strip at one corner).
    #[test]
    fn cleaned_components_equal_the_edge_connected_ones() {
        let mut mesh = TriMesh::default();
        strip(&mut mesh, 0.0, 6);
        strip(&mut mesh, 20.0, 4);
        strip(&mut mesh, 40.0, 9);
        // A fin: a third face on the first strip's inner edge (1, 2).
        let apex = mesh.positions.len() as u32;
        mesh.positions.push(DVec3::new(0.5, 0.5, 1.0));
        mesh.triangles.push([1, 2, apex]);
        // A pinch: a triangle touching the second strip at one corner only.
        let corner = (2 * 6 + 2) as u32;
        let base = mesh.positions.len() as u32;
        mesh.positions.push(DVec3::new(19.0, -1.0, 0.0));
        mesh.positions.push(DVec3::new(18.0, -1.0, 0.0));
        mesh.triangles.push([corner, base, base + 1]);
        let cleaned = crate::mesh::clean::clean(&mesh, &Default::default());
        assert!(cleaned.report.non_manifold_edges_split > 0);
        assert!(cleaned.report.pinch_vertices_split > 0);
        let by_table = connected_components(&cleaned.mesh);
        let by_clean = cleaned_components(&cleaned);
        assert_eq!(by_table.len(), by_clean.len());
        assert!(by_table.len() >= 4, "{} pieces", by_table.len());
        for (a, b) in by_table.iter().zip(&by_clean) {
            assert_eq!(a.triangles, b.triangles);
            assert_eq!(a.positions, b.positions);
        }
    }
}
