//! Sharp edges of a mesh (Hoppe et al. 1994): interior edges whose two faces meet at a
//! dihedral angle (the angle between their normals) above a threshold, kept where they
//! form connected sets of at least a few edges. A short sharp run is scan noise or a
//! sliver triangle far more often than a machined edge, and a control mesh could not
//! carry it anyway. A set is cut where its line turns sharply with no third sharp edge
//! there (a zig-zag along a thin ridge, not a feature line; `KINK_DEG`), and each piece
//! must be long enough on its own.
//!
//! The defaults (60 degrees, 12 edges) are measured: at 40 degrees and 4 edges the smooth
//! models get spurious creases (fertility.off 49 edges, bun_zipper.ply 338, from scan
//! noise on sub-millimetre faces); at 50 degrees fertility has none but bun_zipper still
//! 116 (46 in sets of 12 or more); at 60 degrees and 12 edges both have none, while machined
//! edges (90 degrees) keep a wide margin. Not every scan is that clean: at 60 degrees
//! camelhead.off keeps 14 control crease edges and chin_tri.ply 8. Chamfers of 45-degree
//! steps, and the 60-degree edges of a hexagonal prism (at the threshold itself), need a
//! lower angle.
//!
//! A second, relative rule catches such edges without lowering the angle. An edge turning
//! by more than `relative_min_deg` is sharp too where
//! - it turns `relative_ratio` times as much as the edges beside it (the upper median of the
//!   other edges of its two faces): a machined edge between flat or gently curved faces
//!   stands out however shallow it is (fandisk's 22-degree blade edge beside faces turning
//!   by under 5), while a coarse tessellation of a smooth surface turns by about as much
//!   at every edge and scan noise turns the edges around a bump as much as the bump's own;
//! - no edge at its faces' corners turns the other way by half as much: a convex edge
//!   beside a concave one is a step a face or two wide (a scan line, a terrace of noise);
//! - edges at the two corners off it do not both turn the same way by 0.8 as much: every
//!   ring of a coarse cylinder's facets turns alike (a 20-gon torus, a CAD export), while
//!   a chamfer's edge has its twin on one side only;
//! - it lies in a connected set of at least `min_edges` such edges of its own, so that one
//!   shallow edge beside a steep set (a scan rim's jag) does not join it.
//!
//! At 15 degrees and 6 times the rule adds no crease edge on fertility, decimated-max,
//! camelhead, bun_zipper, chin_tri, a 139k-point bunny with 40 um of noise or a sheet of
//! structured noise or a 60 x 20 torus, where a 20-degree threshold tags hundreds; on
//! fandisk (not tuned on) it adds the blade's edges, and the fit's RMS at 5 and 10 %
//! controls drops by 14 and 30 % (at 2 % it is unchanged).
//! The rule does not find right angles at a box's corners (two of the faces' other edges
//! are creases there): the angle does.

use super::stats::UnionFind;
use super::topology::{Topology, NONE};
use super::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// What counts as a crease.
#[derive(Clone, Debug, PartialEq)]
pub struct CreaseOptions {
    /// Edges whose face normals differ by more than this are sharp. 0 (or any value not
    /// above 0) turns crease detection off.
    pub angle_deg: f64,
    /// Connected sets of sharp edges with fewer edges than this are dropped as noise.
    pub min_edges: usize,
    /// The relative rule (module docs): an edge turning by more than this ...
    pub relative_min_deg: f64,
    /// ... and by this many times the median turn of the other edges of its two faces is
    /// sharp too. 0 (or any value not above 1) turns the rule off.
    pub relative_ratio: f64,
}

impl CreaseOptions {
    /// Whether crease edges are wanted at all (`angle_deg` above 0).
    pub fn on(&self) -> bool {
        self.angle_deg > 0.0
    }
}

impl Default for CreaseOptions {
    fn default() -> Self {
        Self {
            angle_deg: 60.0,
            min_edges: 12,
            relative_min_deg: 15.0,
            relative_ratio: 6.0,
        }
    }
}

/// The dihedral angle (degrees, 0 for a flat edge) between the faces of half-edge `h`
/// and its twin; `None` on the boundary or at a degenerate face.
pub fn dihedral_deg(mesh: &TriMesh, topo: &Topology, h: u32) -> Option<f64> {
    let t = topo.twin[h as usize];
    if t == NONE {
        return None;
    }
    let normal = |f: u32| -> DVec3 {
        let p = topo.triangles[f as usize].map(|v| mesh.positions[v as usize]);
        (p[1] - p[0]).cross(p[2] - p[0])
    };
    let (a, b) = (normal(h / 3), normal(t / 3));
    if a.length_squared() == 0.0 || b.length_squared() == 0.0 {
        return None;
    }
    Some(a.angle_between(b).to_degrees())
}

/// The crease edges of `mesh` (pairs of vertex indices, low first, sorted).
pub fn detect_creases(mesh: &TriMesh, topo: &Topology, opts: &CreaseOptions) -> Vec<[u32; 2]> {
    if !opts.on() {
        return Vec::new();
    }
    let turn = signed_turns(mesh, topo);
    let extremes = turn_extremes(&turn, topo);
    // Each edge on its own, in parallel, the edges kept in edge order.
    let judged: Vec<([u32; 2], Option<Sharp>)> = topo
        .edges()
        .into_par_iter()
        .map(|(a, b, h)| {
            (
                [a.min(b), a.max(b)],
                sharpness(&turn, &extremes, topo, h, opts),
            )
        })
        .collect();
    let mut by_angle = Vec::new();
    let mut by_relative = Vec::new();
    for (edge, sharp) in judged {
        match sharp {
            Some(Sharp::Angle) => by_angle.push(edge),
            Some(Sharp::Relative) => by_relative.push(edge),
            None => {}
        }
    }
    let min_edges = opts.min_edges.max(1);
    // A relative edge has to be part of a feature line of its own: one shallow edge
    // beside a steep set (a rim's jag) is not.
    let mut sharp = by_angle;
    sharp.extend(in_large_sets(by_relative, &mesh.positions, min_edges));
    let mut kept = in_large_sets(sharp, &mesh.positions, min_edges);
    kept.sort_unstable();
    kept
}

/// The edges of `edges` in connected sets of at least `min_edges` edges, where two edges
/// are connected through a shared vertex, except at a vertex where only they meet and the
/// line turns by more than `KINK_DEG` (see `KINK_DEG`).
fn in_large_sets(edges: Vec<[u32; 2]>, positions: &[DVec3], min_edges: usize) -> Vec<[u32; 2]> {
    crease_sets(&edges, positions)
        .into_iter()
        .filter(|set| set.len() >= min_edges)
        .flatten()
        .collect()
}

/// `edges` grouped into the connected sets `detect_creases` keeps or drops whole (see
/// `in_large_sets`), each set's edges in the order given.
pub fn crease_sets(edges: &[[u32; 2]], positions: &[DVec3]) -> Vec<Vec<[u32; 2]>> {
    let mut lines = joined_lines(edges, positions);
    let mut slot = vec![usize::MAX; edges.len()];
    let mut sets: Vec<Vec<[u32; 2]>> = Vec::new();
    for (k, e) in edges.iter().enumerate() {
        let root = lines.find(k);
        if slot[root] == usize::MAX {
            slot[root] = sets.len();
            sets.push(Vec::new());
        }
        sets[slot[root]].push(*e);
    }
    sets
}

/// The edges of `edges` (by index) joined into sets as `in_large_sets` says.
fn joined_lines(edges: &[[u32; 2]], positions: &[DVec3]) -> UnionFind {
    let mut at: Vec<Vec<usize>> = vec![Vec::new(); positions.len()];
    for (k, &[a, b]) in edges.iter().enumerate() {
        for v in [a, b] {
            if let Some(list) = at.get_mut(v as usize) {
                list.push(k);
            }
        }
    }
    let mut lines = UnionFind::new(edges.len());
    for (v, incident) in at.iter().enumerate() {
        if let [e, f] = incident[..] {
            let far = |k: usize| {
                let [a, b] = edges[k];
                positions[(a ^ b ^ v as u32) as usize]
            };
            let p = positions[v];
            if (p - far(e)).angle_between(far(f) - p).to_degrees() > KINK_DEG {
                continue;
            }
        }
        for pair in incident.windows(2) {
            lines.union(pair[0], pair[1]);
        }
    }
    lines
}

/// A line of sharp edges turning by more than this at a vertex where no third sharp edge
/// meets it is cut there (`in_large_sets`). A feature line of a machined part is a smooth
/// curve between corners, and even a hexagon's sides, the coarsest polygon a round edge is
/// tessellated into, turn by 60 degrees and stay one line; its corners are where three or
/// more lines meet.
/// A zig-zag of sharp edges is the coarse sampling of a thin ridge (a dragon's spines and
/// claws at 5k vertices) or noise: its pieces between the kinks must each be a long enough
/// set of their own. Measured on Stanford's dragon at 5k vertices (not tuned on before):
/// 106 of the 161 vertices inside its sharp lines turned by over 45 degrees (61 by over
/// 75), and tagging them left the fit's RMS at 1.33 times the decimated mesh's (0.65 with
/// the cut); fandisk's feature lines are unchanged by it.
const KINK_DEG: f64 = 60.0;

/// Which rule makes an edge sharp.
enum Sharp {
    Angle,
    Relative,
}

/// Whether the edge of half-edge `h` is sharp by the angle or by the relative rule, with
/// `turn` the signed dihedral angle of every half-edge (`signed_turns`) and `extremes`
/// the largest convex and concave turn at every vertex (`turn_extremes`).
fn sharpness(
    turn: &[Option<f64>],
    extremes: &[[f64; 2]],
    topo: &Topology,
    h: u32,
    opts: &CreaseOptions,
) -> Option<Sharp> {
    let signed = turn[h as usize]?;
    let d = signed.abs();
    if d > opts.angle_deg {
        return Some(Sharp::Angle);
    }
    if opts.relative_ratio.is_nan() || opts.relative_ratio <= 1.0 || d <= opts.relative_min_deg {
        return None;
    }
    let t = topo.twin[h as usize];
    let beside: Vec<f64> = [h, t]
        .iter()
        .flat_map(|&e| {
            let face = e - e % 3;
            [face + (e + 1) % 3, face + (e + 2) % 3]
        })
        .filter_map(|e| turn[e as usize])
        .collect();
    if beside.len() < 2 {
        return None;
    }
    let mut sizes: Vec<f64> = beside.iter().map(|b| b.abs()).collect();
    sizes.sort_by(f64::total_cmp);
    // The upper median: a neighbour on the same crease (where it bends, or a chamfer's
    // other edge) does not hide the edge ...
    let typical = sizes[sizes.len() / 2];
    // ... but one turning the other way at its faces' corners does: a step one or two faces
    // wide (a scan line, a terrace of structured noise) is a convex edge beside a concave
    // one.
    let [same, other] = sides_of(signed);
    let corners = [h, t].map(|e| topo.triangles[(e / 3) as usize]);
    let against = corners
        .iter()
        .flatten()
        .map(|&v| extremes[v as usize][other])
        .fold(0.0_f64, f64::max);
    // So do edges turning the same way at both corners off it: a coarse tessellation of a
    // cylinder turns by as much at every ring of edges, while a chamfer's edge has its
    // twin on one side only.
    let along = [h, t]
        .map(|e| {
            extremes[topo.triangles[(e / 3) as usize][((e % 3 + 2) % 3) as usize] as usize][same]
        })
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    let stands_out = d >= opts.relative_ratio * typical.max(RELATIVE_FLOOR_DEG)
        && d >= AGAINST_RATIO * against
        && d > ALONG_RATIO * along;
    stands_out.then_some(Sharp::Relative)
}

/// The relative rule's edges turn by at least this many times as much as any edge at
/// their faces' corners turning the other way.
const AGAINST_RATIO: f64 = 2.0;

/// Per half-edge, its dihedral angle in degrees, positive where the edge is convex (the
/// far face bends away behind the near face's plane), negative where it is concave;
/// `None` on the boundary or at a degenerate face.
fn signed_turns(mesh: &TriMesh, topo: &Topology) -> Vec<Option<f64>> {
    (0..topo.twin.len() as u32)
        .into_par_iter()
        .map(|h| {
            let d = dihedral_deg(mesh, topo, h)?;
            let t = topo.twin[h as usize];
            let near = topo.triangles[(h / 3) as usize].map(|v| mesh.positions[v as usize]);
            let far = topo.triangles[(t / 3) as usize];
            // The far face's corner off the edge: its half-edge t runs along the edge.
            let off = mesh.positions[far[((t % 3 + 2) % 3) as usize] as usize];
            let normal = (near[1] - near[0]).cross(near[2] - near[0]);
            Some(if normal.dot(off - near[0]) <= 0.0 {
                d
            } else {
                -d
            })
        })
        .collect()
}

/// Per vertex, the largest convex and the largest concave turn (magnitudes) of the edges
/// at it.
fn turn_extremes(turn: &[Option<f64>], topo: &Topology) -> Vec<[f64; 2]> {
    let mut extremes = vec![[0.0_f64; 2]; topo.vertex_count];
    for (h, t) in turn.iter().enumerate() {
        let Some(t) = *t else { continue };
        let side = usize::from(t < 0.0);
        let face = topo.triangles[h / 3];
        for v in [face[h % 3], face[(h + 1) % 3]] {
            let e = &mut extremes[v as usize][side];
            *e = e.max(t.abs());
        }
    }
    extremes
}

/// The index in `turn_extremes` of a turn's own side and of the other one.
fn sides_of(signed: f64) -> [usize; 2] {
    if signed < 0.0 {
        [1, 0]
    } else {
        [0, 1]
    }
}

/// Edges turning the same way at both corners off an edge by more than this share of its
/// turn make it a ring of a coarse tessellation (a cylinder's facets turn alike).
const ALONG_RATIO: f64 = 1.25;

/// Neighbours turning by less than this count as turning by this much in the relative
/// rule, so that faint edges between exactly flat faces are not sharp.
const RELATIVE_FLOOR_DEG: f64 = 1.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube, `n` x `n` cells per face, two triangles per cell.
    fn cube(n: usize) -> TriMesh {
        let mut ids = std::collections::HashMap::new();
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for axis in 0..3 {
            for side in [0usize, 1] {
                let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
                let (a, b) = if side == 1 { (a, b) } else { (b, a) };
                let mut id = |i: usize, j: usize| -> u32 {
                    let mut key = [0usize; 3];
                    key[axis] = side * n;
                    key[a] = i;
                    key[b] = j;
                    *ids.entry(key).or_insert_with(|| {
                        positions.push(DVec3::new(key[0] as f64, key[1] as f64, key[2] as f64));
                        (positions.len() - 1) as u32
                    })
                };
                for i in 0..n {
                    for j in 0..n {
                        let (p, q, s, t) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                        triangles.push([p, q, s]);
                        triangles.push([p, s, t]);
                    }
                }
            }
        }
        TriMesh::new(positions, triangles)
    }

    #[test]
    fn a_cube_has_its_twelve_edges_and_nothing_else() {
        let mesh = cube(3);
        let topo = Topology::from_mesh(&mesh).expect("manifold");
        let creases = detect_creases(&mesh, &topo, &CreaseOptions::default());
        assert_eq!(creases.len(), 12 * 3);
        for [a, b] in creases {
            let (p, q) = (mesh.positions[a as usize], mesh.positions[b as usize]);
            let shared = (0..3)
                .filter(|&k| p[k] == q[k] && (p[k] == 0.0 || p[k] == 3.0))
                .count();
            assert_eq!(shared, 2, "{p} - {q} is not on a cube edge");
        }
        let off = CreaseOptions {
            angle_deg: 0.0,
            ..Default::default()
        };
        assert!(detect_creases(&mesh, &topo, &off).is_empty());
        // Above the edges' angle, and with the relative rule off (right angles between
        // flat faces stand out, so the rule alone keeps most of them).
        let steep = CreaseOptions {
            angle_deg: 95.0,
            relative_ratio: 0.0,
            ..Default::default()
        };
        assert!(detect_creases(&mesh, &topo, &steep).is_empty());
    }

    #[test]
    fn short_sharp_runs_are_dropped() {
        let mut mesh = cube(6);
        let topo = Topology::from_mesh(&mesh).expect("manifold");
        // A spike in the middle of a face: its 12 edges are sharp but few.
        let v = (0..mesh.positions.len())
            .find(|&v| mesh.positions[v] == DVec3::new(3.0, 3.0, 6.0))
            .expect("a face-interior vertex") as u32;
        mesh.positions[v as usize].z += 1.5;
        let opts = |min_edges| CreaseOptions {
            angle_deg: 20.0,
            min_edges,
            ..Default::default()
        };
        let all = detect_creases(&mesh, &topo, &opts(1));
        assert!(all.iter().any(|e| e.contains(&v)));
        let kept = detect_creases(&mesh, &topo, &opts(20));
        assert_eq!(kept.len(), 12 * 6, "the cube's edges are one connected set");
        let ring = topo.ring(v);
        assert!(kept
            .iter()
            .all(|e| !e.contains(&v) && (!ring.contains(&e[0]) || !ring.contains(&e[1]))));
        assert!(detect_creases(&mesh, &topo, &opts(100)).is_empty());
    }

    /// A unit square sheet, `n` x `n` cells (`n` even), flat for x <= 1/2 and rising by
    /// `rise(x)` beyond; two triangles per cell.
    fn sheet(n: usize, rise: impl Fn(f64) -> f64) -> TriMesh {
        crate::testdata::height_grid(n as u32, |x, _| rise(x))
    }

    #[test]
    fn a_shallow_fold_between_flat_faces_is_a_crease_by_the_relative_rule() {
        let n = 20;
        let slope = 25f64.to_radians().tan();
        let mesh = sheet(n, |x| slope * (x - 0.5).max(0.0));
        let topo = Topology::from_mesh(&mesh).expect("manifold");
        let found = detect_creases(&mesh, &topo, &CreaseOptions::default());
        assert_eq!(found.len(), n, "the fold's edges: {found:?}");
        for [a, b] in &found {
            for v in [a, b] {
                assert!((mesh.positions[*v as usize].x - 0.5).abs() < 1e-12);
            }
        }
        let angle_only = CreaseOptions {
            relative_ratio: 0.0,
            ..Default::default()
        };
        assert!(detect_creases(&mesh, &topo, &angle_only).is_empty());
    }

    #[test]
    fn a_step_one_face_wide_is_not_a_crease() {
        // A convex edge beside a concave one, one cell apart, both turning by 25 degrees:
        // a scan line's terrace, not a machined edge.
        let n = 20;
        let h = 25f64.to_radians().tan() / n as f64;
        let mesh = sheet(n, |x| (n as f64 * h * (x - 0.5)).clamp(0.0, h));
        let topo = Topology::from_mesh(&mesh).expect("manifold");
        assert!(detect_creases(&mesh, &topo, &CreaseOptions::default()).is_empty());
        // The same turn spread over a ramp three cells wide is two creases.
        let wide = sheet(n, |x| (n as f64 * h * (x - 0.5)).clamp(0.0, 3.0 * h));
        let topo = Topology::from_mesh(&wide).expect("manifold");
        assert_eq!(
            detect_creases(&wide, &topo, &CreaseOptions::default()).len(),
            2 * n
        );
    }

    #[test]
    fn the_rings_of_a_coarse_torus_are_not_creases() {
        // 20 facets around the tube: every ring of edges turns by 18 degrees, and near the
        // top and bottom the edges across them hardly turn at all.
        let mesh = crate::mesh::simplify::tests::torus(60, 20);
        let topo = Topology::from_mesh(&mesh).expect("manifold");
        assert!(detect_creases(&mesh, &topo, &CreaseOptions::default()).is_empty());
        let by_angle_at_15_degrees = CreaseOptions {
            angle_deg: 15.0,
            relative_ratio: 0.0,
            ..Default::default()
        };
        assert!(!detect_creases(&mesh, &topo, &by_angle_at_15_degrees).is_empty());
    }

    /// A polyline from the origin along `turns`: each step one unit long, turning by the
    /// given angle (degrees, in the xy plane) before it; its edges and positions.
    fn polyline(turns: &[f64]) -> (Vec<[u32; 2]>, Vec<DVec3>) {
        let mut positions = vec![DVec3::ZERO];
        let mut heading = 0.0f64;
        for t in turns {
            heading += t.to_radians();
            let last = positions[positions.len() - 1];
            positions.push(last + DVec3::new(heading.cos(), heading.sin(), 0.0));
        }
        let edges = (0..turns.len() as u32).map(|k| [k, k + 1]).collect();
        (edges, positions)
    }

    #[test]
    fn a_zig_zag_of_sharp_edges_is_no_feature_line() {
        let sets = |turns: &[f64]| {
            let (edges, positions) = polyline(turns);
            in_large_sets(edges, &positions, 12).len()
        };
        assert_eq!(sets(&[0.0; 20]), 20, "a straight line");
        // Turning by 55 degrees at every vertex (under a hexagon's 60): a coarse round
        // edge, still one line.
        let hexagonal: Vec<f64> = (0..20).map(|k| if k == 0 { 0.0 } else { 55.0 }).collect();
        assert_eq!(sets(&hexagonal), 20);
        // Turning back and forth by 90 degrees: cut at every vertex, nothing is left.
        let zig_zag: Vec<f64> = (0..20)
            .map(|k| {
                if k == 0 {
                    0.0
                } else if k % 2 == 1 {
                    90.0
                } else {
                    -90.0
                }
            })
            .collect();
        assert_eq!(sets(&zig_zag), 0);
        // One right-angle kink between two long runs: both stay, as lines of their own ...
        let mut kinked = vec![0.0; 30];
        kinked[15] = 90.0;
        assert_eq!(sets(&kinked), 30);
        // ... and two short runs do not add up to a long one.
        let mut short = vec![0.0; 16];
        short[8] = 90.0;
        assert_eq!(sets(&short), 0);
        // Where a third sharp edge meets the kink it is a corner, and joins the runs.
        let (mut edges, mut positions) = polyline(&short);
        positions.push(positions[8] + DVec3::Z);
        edges.push([8, positions.len() as u32 - 1]);
        assert_eq!(in_large_sets(edges, &positions, 12).len(), 17);
    }
}
