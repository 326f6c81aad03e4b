//! Faces that repeat another face's three vertices, and which of them `clean` drops.
//!
//! A repeat in the same orientation is a duplicate: the first in face order stays. A face
//! and its reverse are the two sides of a sheet of zero thickness. Volumetric
//! reconstructions leave such sheets where a part thinner than their voxels collapsed (a
//! fin, a membrane between two parts that touch): Stanford's `dragon_vrip_res2` has 1,400
//! of them, and keeping one side of each left 2,140 edges with three faces and 1,700
//! boundary edges, which the non-manifold split then cut into a thousand holes. As
//! oriented chains the two sides cancel: dropping both leaves every edge of the surface
//! around them with its two faces, the boundary of the rest unchanged. A sheet that stands
//! alone (a double-sided panel as exported for rendering) has no surface around it: there
//! one side stays. Which case holds is decided per connected sheet: it goes when keeping
//! one side of it would give some edge more than two faces, as a sheet hanging off a
//! surface does.

use super::edge_table::EdgeTable;
use super::stats::UnionFind;

/// What [`repeated_faces`] found.
pub(super) struct Repeats {
    /// Per face, whether `clean` drops it.
    pub dropped: Vec<bool>,
    /// Faces dropped as duplicates (a repeat in the same orientation, or the other side
    /// of a sheet one side of which stays).
    pub duplicates: usize,
    /// Faces dropped as both sides of a sheet of zero thickness.
    pub sheet_faces: usize,
}

/// Which faces of `faces` (indices below `vertex_count`) repeat another's vertices, and
/// which of those go (see the module docs).
pub(super) fn repeated_faces(faces: &[[u32; 3]], vertex_count: usize) -> Repeats {
    let mut repeats = Repeats {
        dropped: vec![false; faces.len()],
        duplicates: 0,
        sheet_faces: 0,
    };
    // Per face of a sheet whose sides cancel exactly: whether it is its run's first face
    // (the side kept when the sheet stands alone).
    let mut sheet: Vec<(u32, bool)> = Vec::new();
    for run in runs_of_equal_vertex_sets(faces, vertex_count) {
        let (forward, backward): (Vec<u32>, Vec<u32>) = run
            .iter()
            .partition(|&&f| is_ascending_cycle(faces[f as usize]));
        let pairs = forward.len().min(backward.len());
        if forward.len() == backward.len() {
            sheet.extend(run.iter().map(|&f| (f, f == run[0])));
            continue;
        }
        // The unpaired faces of the majority orientation: the first stays.
        let unpaired = if forward.len() > backward.len() {
            &forward[pairs..]
        } else {
            &backward[pairs..]
        };
        for &f in &run {
            repeats.dropped[f as usize] = f != unpaired[0];
        }
        repeats.sheet_faces += 2 * pairs;
        repeats.duplicates += unpaired.len() - 1;
    }
    if !sheet.is_empty() {
        resolve_sheets(faces, vertex_count, &sheet, &mut repeats);
    }
    repeats
}

/// Whether triangle `t` runs through its vertices in ascending cyclic order (so that two
/// faces with the same vertices agree in orientation exactly when both do or both don't).
fn is_ascending_cycle(t: [u32; 3]) -> bool {
    let first = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
    t[(first + 1) % 3] < t[(first + 2) % 3]
}

/// The faces with the same vertex set, per set of two or more, in face order. Faces are
/// grouped by their lowest vertex (a counting sort, no hashing) and each small group
/// sorted by the other two.
fn runs_of_equal_vertex_sets(faces: &[[u32; 3]], vertex_count: usize) -> Vec<Vec<u32>> {
    let sorted = |t: &[u32; 3]| {
        let mut key = *t;
        key.sort_unstable();
        key
    };
    let mut start = vec![0u32; vertex_count + 1];
    for t in faces {
        start[sorted(t)[0] as usize + 1] += 1;
    }
    for v in 0..vertex_count {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut entries = vec![(0u32, 0u32, 0u32); faces.len()];
    for (f, t) in faces.iter().enumerate() {
        let key = sorted(t);
        let slot = &mut fill[key[0] as usize];
        entries[*slot as usize] = (key[1], key[2], f as u32);
        *slot += 1;
    }
    drop(fill);
    let mut runs = Vec::new();
    for v in 0..vertex_count {
        let group = &mut entries[start[v] as usize..start[v + 1] as usize];
        if group.len() < 2 {
            continue;
        }
        group.sort_unstable();
        for same in group.chunk_by(|a, b| (a.0, a.1) == (b.0, b.1)) {
            if same.len() > 1 {
                runs.push(same.iter().map(|e| e.2).collect());
            }
        }
    }
    runs
}

/// Drops both sides of every connected sheet (faces of `sheet`, with whether each is its
/// run's first) for which keeping one side would give an edge more than two faces, and the
/// other side of every other sheet.
fn resolve_sheets(
    faces: &[[u32; 3]],
    vertex_count: usize,
    sheet: &[(u32, bool)],
    repeats: &mut Repeats,
) {
    // 0: no sheet face, 1: a sheet face, 2: a sheet run's first face.
    let mut role = vec![0u8; faces.len()];
    for &(f, first) in sheet {
        role[f as usize] = 1 + u8::from(first);
    }
    let edges = EdgeTable::new(faces, vertex_count);
    let mut sheets = UnionFind::new(faces.len());
    let mut overfull = Vec::new();
    for e in 0..edges.len() {
        let on_edge = edges.halves(e).iter().map(|&h| h as usize / 3);
        let mut sheet_face = None;
        let mut kept = 0;
        for f in on_edge {
            match role[f] {
                0 => kept += usize::from(!repeats.dropped[f]),
                r => {
                    kept += usize::from(r == 2);
                    if let Some(g) = sheet_face {
                        sheets.union(g, f);
                    }
                    sheet_face = Some(f);
                }
            }
        }
        if let Some(f) = sheet_face.filter(|_| kept > 2) {
            overfull.push(f);
        }
    }
    let mut goes = vec![false; faces.len()];
    for f in overfull {
        let root = sheets.find(f);
        goes[root] = true;
    }
    for &(f, first) in sheet {
        let f = f as usize;
        let root = sheets.find(f);
        if goes[root] {
            repeats.dropped[f] = true;
            repeats.sheet_faces += 1;
        } else if !first {
            repeats.dropped[f] = true;
            repeats.duplicates += 1;
        }
    }
}
