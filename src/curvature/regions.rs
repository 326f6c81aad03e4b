//! Sampling on a parameter lattice, region labelling and boundary tracing.
//!
//! The samples form a triangulated lattice: a rectangular grid (two triangles per cell)
//! or the triangular lattice of the reference triangle. Regions are connected sets of
//! samples of one type, connected along lattice edges. A region's boundary is traced like
//! a crack-following chain code: it crosses every lattice edge whose ends lie in different
//! regions at the edge's midpoint, passes through the centroid of triangles whose three
//! corners lie in three regions, and follows the domain boundary where the region meets
//! it. Each region gets closed loops, counter-clockwise in (u, v) around the region
//! (outer boundaries counter-clockwise, holes clockwise), evaluated on the surface.

use super::{classify, curvature, Curvature, DerivativeSurface, Domain, RegionKind, ZeroTolerance};
use crate::surface::bezier::{lattice_index, lattice_points, lattice_triangles};
use glam::DVec3;
use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

/// Multiply-rotate hashing of small integer keys (the Firefox/rustc scheme): the keys are
/// ours, not an attacker's, and SipHash would dominate boundary tracing.
#[derive(Default)]
struct FxHasher(u64);

impl Hasher for FxHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u8(&mut self, x: u8) {
        self.write_u64(u64::from(x));
    }
    fn write_u32(&mut self, x: u32) {
        self.write_u64(u64::from(x));
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }
}

type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FxHasher>>;
type FastSet<K> = HashSet<K, BuildHasherDefault<FxHasher>>;

/// Sample parameters, their triangles (counter-clockwise in (u, v)) and the domain
/// boundary as a counter-clockwise vertex loop.
#[derive(Clone, Debug)]
pub struct Lattice {
    /// Sample parameters.
    pub params: Vec<(f64, f64)>,
    /// Counter-clockwise triangles of samples.
    pub triangles: Vec<[u32; 3]>,
    /// Directed domain-boundary edges, the domain on their left (one loop for a rectangle
    /// or triangle, several for a union of grid cells with holes).
    pub boundary: Vec<(u32, u32)>,
    /// Rectangle: (rows, cols) of the row-major grid; triangle: (n + 1, 0).
    pub shape: (usize, usize),
    /// Per triangle, its corners' parameters in its own chart, for surfaces whose samples
    /// are welded across per-face charts (see [`super::OwnLattice::charts`]); `None` when
    /// `params` are one global chart.
    pub charts: Option<Vec<[(f64, f64); 3]>>,
}

impl Lattice {
    /// `n x n` samples over a rectangle (n >= 2), row-major with u along rows.
    pub(crate) fn rectangle(u: (f64, f64), v: (f64, f64), n: usize) -> Self {
        let n = n.max(2);
        let at = |a: (f64, f64), k: usize| a.0 + (a.1 - a.0) * k as f64 / (n - 1) as f64;
        let params = (0..n * n).map(|k| (at(u, k / n), at(v, k % n))).collect();
        let id = |r: usize, c: usize| (r * n + c) as u32;
        // Counter-clockwise in (u, v): along v = v0 with u rising, then u = u1, ...
        let mut boundary: Vec<u32> = (0..n - 1).map(|r| id(r, 0)).collect();
        boundary.extend((0..n - 1).map(|c| id(n - 1, c)));
        boundary.extend((1..n).rev().map(|r| id(r, n - 1)));
        boundary.extend((1..n).rev().map(|c| id(0, c)));
        let boundary = loop_edges(&boundary);
        Self {
            params,
            triangles: crate::bspline::surface::grid_triangles(n, n),
            boundary,
            shape: (n, n),
            charts: None,
        }
    }

    /// The triangular lattice with `n` samples a side (n >= 2) over the reference triangle,
    /// in the project's lattice order (`surface::bezier::lattice_index`).
    pub fn triangle(n: usize) -> Self {
        let s = n.max(2) - 1;
        let params = lattice_points(s)
            .into_iter()
            .map(|(i, j)| (i as f64 / s as f64, j as f64 / s as f64))
            .collect();
        let id = |i: usize, j: usize| lattice_index(s, i, j) as u32;
        // (0,0) -> (s,0) along v = 0, then the hypotenuse to (0,s), then down u = 0.
        let mut boundary: Vec<u32> = (0..s).map(|i| id(i, 0)).collect();
        boundary.extend((0..s).map(|j| id(s - j, j)));
        boundary.extend((1..=s).rev().map(|j| id(0, j)));
        let boundary = loop_edges(&boundary);
        Self {
            params,
            triangles: lattice_triangles(s),
            boundary,
            shape: (s + 1, 0),
            charts: None,
        }
    }

    /// A counter-clockwise triangulation given by the surface (cells of a grid): the
    /// boundary is every edge of one triangle only.
    pub fn triangulated(params: Vec<(f64, f64)>, triangles: Vec<[u32; 3]>) -> Self {
        let mut count: FastMap<(u32, u32), u32> = FastMap::default();
        for t in &triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let mut boundary = Vec::new();
        for t in &triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if count.get(&(a.min(b), a.max(b))) == Some(&1) {
                    boundary.push((a, b));
                }
            }
        }
        let n = params.len();
        Self {
            params,
            triangles,
            boundary,
            shape: (n, 0),
            charts: None,
        }
    }

    /// The lattice matching a surface's domain.
    pub fn for_surface(surface: &dyn DerivativeSurface, n: usize) -> Self {
        match surface.domain() {
            Domain::Rectangle { u, v } => Self::rectangle(u, v, n),
            Domain::Triangle => Self::triangle(n),
            Domain::Cells => {
                let own = surface.own_lattice(n);
                Self {
                    charts: own.charts,
                    ..Self::triangulated(own.params, own.triangles)
                }
            }
        }
    }

    /// Vertex adjacency (CSR) from the triangles' edges. Interior edges are listed twice
    /// (once from each triangle): harmless for connectivity, and it spares a sort.
    fn adjacency(&self) -> (Vec<u32>, Vec<u32>) {
        let n = self.params.len();
        let mut offs = vec![0u32; n + 1];
        for t in &self.triangles {
            for &v in t {
                offs[v as usize + 1] += 2;
            }
        }
        for i in 0..n {
            offs[i + 1] += offs[i];
        }
        let mut fill = offs.clone();
        let mut nbr = vec![0u32; offs[n] as usize];
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k] as usize, t[(k + 1) % 3]);
                let c = t[(k + 2) % 3];
                nbr[fill[a] as usize] = b;
                nbr[fill[a] as usize + 1] = c;
                fill[a] += 2;
            }
        }
        (offs, nbr)
    }
}

#[derive(Clone, Debug)]
/// How a surface is sampled and its regions cleaned up.
pub struct AnalysisOptions {
    /// Samples per side of the parameter lattice.
    pub grid: usize,
    /// Relative zero tolerance (see [`ZeroTolerance::relative`]).
    pub zero_eps: f64,
    /// Regions with fewer samples are merged into the neighbour they share most lattice
    /// edges with (noise would otherwise make hundreds of one-sample regions).
    pub min_region: usize,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        Self {
            grid: 201,
            zero_eps: 1e-6,
            min_region: 8,
        }
    }
}

#[derive(Clone, Debug, serde::Serialize)]
/// A connected region of one type with its boundary loops.
pub struct Region {
    /// Region id (the index in `Analysis::regions`).
    pub id: u32,
    /// Its type.
    pub kind: RegionKind,
    /// Samples in it.
    pub samples: usize,
    /// Closed loops (last point = first) on the surface.
    pub loops: Vec<Vec<DVec3>>,
    /// The same loops in parameter space.
    pub param_loops: Vec<Vec<(f64, f64)>>,
}

#[derive(Clone, Debug)]
/// A curvature analysis: samples, their curvature and type, and the regions.
pub struct Analysis {
    /// The sampling.
    pub lattice: Lattice,
    /// Surface point of every sample.
    pub positions: Vec<DVec3>,
    /// `None` at singular points of the parametrisation.
    pub curvature: Vec<Option<Curvature>>,
    /// Region type per sample after clean-up.
    pub kinds: Vec<RegionKind>,
    /// Region id per sample.
    pub region: Vec<u32>,
    /// The regions, by id.
    pub regions: Vec<Region>,
    /// The zero tolerance used.
    pub tolerance: ZeroTolerance,
    /// Milliseconds spent sampling (derivatives and curvature), labelling (classification,
    /// components, small-region merging) and tracing boundaries.
    pub timings_ms: Timings,
}

#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
/// Milliseconds per stage of an analysis.
pub struct Timings {
    /// Derivatives and curvature of every sample.
    pub sampling: f64,
    /// Classification, components and small-region merging.
    pub labelling: f64,
    /// Boundary loops.
    pub tracing: f64,
}

impl Analysis {
    /// Number of regions of a type.
    pub fn count(&self, kind: RegionKind) -> usize {
        self.regions.iter().filter(|r| r.kind == kind).count()
    }
}

/// Samples the surface, classifies, labels regions and traces their boundaries.
pub fn analyze(surface: &dyn DerivativeSurface, o: &AnalysisOptions) -> Analysis {
    let clock = std::time::Instant::now();
    let ms = |t: std::time::Instant| t.elapsed().as_secs_f64() * 1e3;
    let lattice = Lattice::for_surface(surface, o.grid);
    let derivs = match (surface.domain(), lattice.shape) {
        (Domain::Rectangle { .. }, (rows, cols)) => {
            let us: Vec<f64> = (0..rows).map(|r| lattice.params[r * cols].0).collect();
            let vs: Vec<f64> = (0..cols).map(|c| lattice.params[c].1).collect();
            surface.derivatives_on_grid(&us, &vs)
        }
        (Domain::Triangle | Domain::Cells, _) => surface.derivatives_at(&lattice.params),
    };
    let positions: Vec<DVec3> = derivs.iter().map(|d| d.position).collect();
    let curv: Vec<Option<Curvature>> = {
        use rayon::prelude::*;
        derivs.par_iter().map(curvature).collect()
    };
    let (lo, hi) = positions
        .iter()
        .fold((DVec3::MAX, DVec3::MIN), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    let tolerance = ZeroTolerance::relative(o.zero_eps, (hi - lo).length());
    let sampling = ms(clock);
    let clock = std::time::Instant::now();
    let (offs, nbr) = lattice.adjacency();
    let neighbours = |v: usize| &nbr[offs[v] as usize..offs[v + 1] as usize];

    let mut kinds: Vec<Option<RegionKind>> = curv
        .iter()
        .map(|c| c.map(|c| classify(&c, tolerance)))
        .collect();
    // Singular samples take the type of a classified neighbour (breadth first).
    fill_unclassified(&mut kinds, &neighbours);
    let mut kinds: Vec<RegionKind> = kinds
        .into_iter()
        .map(|k| k.unwrap_or(RegionKind::Convex))
        .collect();

    let mut region = label(&kinds, &neighbours);
    for _ in 0..32 {
        if !merge_small(&mut kinds, &region, o.min_region, &neighbours) {
            break;
        }
        region = label(&kinds, &neighbours);
    }
    let labelling = ms(clock);
    let clock = std::time::Instant::now();
    let regions = trace(surface, &lattice, &positions, &kinds, &region);
    let timings_ms = Timings {
        sampling,
        labelling,
        tracing: ms(clock),
    };
    Analysis {
        timings_ms,
        lattice,
        positions,
        curvature: curv,
        kinds,
        region,
        regions,
        tolerance,
    }
}

fn fill_unclassified<'a>(
    kinds: &mut [Option<RegionKind>],
    neighbours: &impl Fn(usize) -> &'a [u32],
) {
    let mut queue: std::collections::VecDeque<usize> =
        (0..kinds.len()).filter(|&v| kinds[v].is_some()).collect();
    while let Some(v) = queue.pop_front() {
        for &w in neighbours(v) {
            if kinds[w as usize].is_none() {
                kinds[w as usize] = kinds[v];
                queue.push_back(w as usize);
            }
        }
    }
}

/// Connected components of equal type along lattice edges; ids in order of first sample.
fn label<'a>(kinds: &[RegionKind], neighbours: &impl Fn(usize) -> &'a [u32]) -> Vec<u32> {
    let mut region = vec![u32::MAX; kinds.len()];
    let mut next = 0;
    let mut stack = Vec::new();
    for s in 0..kinds.len() {
        if region[s] != u32::MAX {
            continue;
        }
        region[s] = next;
        stack.push(s);
        while let Some(v) = stack.pop() {
            for &w in neighbours(v) {
                let w = w as usize;
                if region[w] == u32::MAX && kinds[w] == kinds[v] {
                    region[w] = next;
                    stack.push(w);
                }
            }
        }
        next += 1;
    }
    region
}

/// Gives every region smaller than `min` the type of the neighbouring region it shares
/// most lattice edges with. Returns whether anything changed.
fn merge_small<'a>(
    kinds: &mut [RegionKind],
    region: &[u32],
    min: usize,
    neighbours: &impl Fn(usize) -> &'a [u32],
) -> bool {
    let count = region.iter().map(|&r| r as usize + 1).max().unwrap_or(0);
    if count <= 1 {
        return false;
    }
    let mut size = vec![0usize; count];
    let mut kind_of = vec![RegionKind::Convex; count];
    for (v, &r) in region.iter().enumerate() {
        size[r as usize] += 1;
        kind_of[r as usize] = kinds[v];
    }
    // Shared lattice edges of each small region with each neighbouring region.
    let mut shared: FastMap<(u32, u32), usize> = FastMap::default();
    for (v, &r) in region.iter().enumerate() {
        if size[r as usize] >= min {
            continue;
        }
        for &w in neighbours(v) {
            let q = region[w as usize];
            if q != r {
                *shared.entry((r, q)).or_default() += 1;
            }
        }
    }
    // Per small region: most shared edges, then the larger neighbour, then the lower id.
    let mut target: Vec<Option<(usize, usize, std::cmp::Reverse<u32>)>> = vec![None; count];
    for (&(r, q), &n) in &shared {
        let key = (n, size[q as usize], std::cmp::Reverse(q));
        let t = &mut target[r as usize];
        if t.is_none_or(|t| key > t) {
            *t = Some(key);
        }
    }
    // Smallest regions first; a region merged this round does not also absorb others.
    let mut small: Vec<u32> = (0..count as u32)
        .filter(|&r| target[r as usize].is_some())
        .collect();
    small.sort_by_key(|&r| (size[r as usize], r));
    let mut new_kind: Vec<Option<RegionKind>> = vec![None; count];
    for r in small {
        let Some((_, _, std::cmp::Reverse(q))) = target[r as usize] else {
            continue;
        };
        if new_kind[q as usize].is_none() {
            new_kind[r as usize] = Some(kind_of[q as usize]);
        }
    }
    let mut changed = false;
    for (v, &r) in region.iter().enumerate() {
        if let Some(k) = new_kind[r as usize] {
            changed |= kinds[v] != k;
            kinds[v] = k;
        }
    }
    changed
}

/// A point of a boundary loop: a lattice vertex (on the domain boundary), the midpoint of a
/// lattice edge, or the centroid of a triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Node {
    Vertex(u32),
    Mid(u32, u32),
    Centroid(u32),
}

fn mid(a: u32, b: u32) -> Node {
    Node::Mid(a.min(b), a.max(b))
}

/// The boundary loops of every region, as surface points and as parameters.
fn trace(
    surface: &dyn DerivativeSurface,
    lattice: &Lattice,
    positions: &[DVec3],
    kinds: &[RegionKind],
    region: &[u32],
) -> Vec<Region> {
    let count = region.iter().map(|&r| r as usize + 1).max().unwrap_or(0);
    let mut size = vec![0usize; count];
    let mut kind_of = vec![RegionKind::Convex; count];
    for (v, &r) in region.iter().enumerate() {
        size[r as usize] += 1;
        kind_of[r as usize] = kinds[v];
    }
    let segments = boundary_segments(lattice, region);
    let loops = follow_loops(&segments.next, count);
    let param = |n: Node| node_param(lattice, &segments.mid_param, n);
    // Every loop point is on the surface: lattice vertices are sampled already, the rest
    // (each shared by two loops) is evaluated once, in parallel.
    let mut extra: Vec<Node> = loops
        .iter()
        .flatten()
        .flatten()
        .copied()
        .filter(|n| !matches!(n, Node::Vertex(_)))
        .collect();
    extra.sort_unstable_by_key(|&n| node_order(n));
    extra.dedup();
    let extra_params: Vec<(f64, f64)> = extra.iter().map(|&n| param(n)).collect();
    let extra_pos: Vec<DVec3> = surface
        .derivatives_at(&extra_params)
        .into_iter()
        .map(|d| d.position)
        .collect();
    let position = |n: Node| match n {
        Node::Vertex(v) => positions[v as usize],
        other => {
            let k = extra
                .binary_search_by_key(&node_order(other), |&m| node_order(m))
                .unwrap_or(0);
            extra_pos[k]
        }
    };
    (0..count)
        .map(|r| Region {
            id: r as u32,
            kind: kind_of[r],
            samples: size[r],
            loops: loops[r]
                .iter()
                .map(|l| l.iter().map(|&n| position(n)).collect())
                .collect(),
            param_loops: loops[r]
                .iter()
                .map(|l| l.iter().map(|&n| param(n)).collect())
                .collect(),
        })
        .collect()
}

/// Directed boundary segments of the regions, and the parameters of edge midpoints in the
/// chart of a triangle holding them.
struct Segments {
    /// (region, start) -> end: the region lies to the left of each segment.
    next: FastMap<(u32, Node), Node>,
    /// With per-face charts the midpoint of an edge must be taken in the chart of a
    /// triangle holding it (its ends' own `params` may be in different charts). Every edge
    /// whose ends differ in region lies in a triangle met by `boundary_segments`, so this
    /// map covers all midpoints of the loops; either triangle of an edge gives the same
    /// surface point.
    mid_param: FastMap<(u32, u32), (f64, f64)>,
}

fn boundary_segments(lattice: &Lattice, region: &[u32]) -> Segments {
    let mut next: FastMap<(u32, Node), Node> = FastMap::default();
    let mut mid_param: FastMap<(u32, u32), (f64, f64)> = FastMap::default();
    for (ti, t) in lattice.triangles.iter().enumerate() {
        let l = [
            region[t[0] as usize],
            region[t[1] as usize],
            region[t[2] as usize],
        ];
        if l[0] == l[1] && l[1] == l[2] {
            continue;
        }
        if let Some(ch) = lattice.charts.as_ref().and_then(|c| c.get(ti)) {
            for c in 0..3 {
                let c1 = (c + 1) % 3;
                let (a, b) = (t[c], t[c1]);
                mid_param.insert(
                    (a.min(b), a.max(b)),
                    (0.5 * (ch[c].0 + ch[c1].0), 0.5 * (ch[c].1 + ch[c1].1)),
                );
            }
        }
        if l[0] != l[1] && l[1] != l[2] && l[0] != l[2] {
            for c in 0..3 {
                let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
                next.insert((l[c], mid(t[c], t[c1])), Node::Centroid(ti as u32));
                next.insert((l[c], Node::Centroid(ti as u32)), mid(t[c2], t[c]));
            }
            continue;
        }
        // Two corners share a region: k is the odd one, i and j follow it counter-clockwise.
        let k = (0..3)
            .find(|&k| l[(k + 1) % 3] == l[(k + 2) % 3])
            .unwrap_or(0);
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        next.insert((l[i], mid(t[j], t[k])), mid(t[k], t[i]));
        next.insert((l[k], mid(t[k], t[i])), mid(t[j], t[k]));
    }
    for &(a, c) in &lattice.boundary {
        let (ra, rc) = (region[a as usize], region[c as usize]);
        if ra == rc {
            next.insert((ra, Node::Vertex(a)), Node::Vertex(c));
        } else {
            next.insert((ra, Node::Vertex(a)), mid(a, c));
            next.insert((rc, mid(a, c)), Node::Vertex(c));
        }
    }
    Segments { next, mid_param }
}

/// Follows the segments into loops per region, starting from the smallest key for
/// determinism.
fn follow_loops(next: &FastMap<(u32, Node), Node>, count: usize) -> Vec<Vec<Vec<Node>>> {
    let mut starts: Vec<(u32, Node)> = next.keys().copied().collect();
    starts.sort_by_key(|&(r, n)| (r, node_order(n)));
    let mut used: FastSet<(u32, Node)> = FastSet::default();
    let mut loops: Vec<Vec<Vec<Node>>> = vec![Vec::new(); count];
    for s in starts {
        if used.contains(&s) {
            continue;
        }
        let (r, mut n) = s;
        let mut lp = vec![n];
        while used.insert((r, n)) {
            match next.get(&(r, n)) {
                Some(&m) => {
                    lp.push(m);
                    n = m;
                }
                None => break,
            }
        }
        loops[r as usize].push(lp);
    }
    loops
}

/// A loop point's surface parameters.
fn node_param(
    lattice: &Lattice,
    mid_param: &FastMap<(u32, u32), (f64, f64)>,
    n: Node,
) -> (f64, f64) {
    let p = &lattice.params;
    match n {
        Node::Vertex(v) => p[v as usize],
        Node::Mid(a, b) => mid_param.get(&(a, b)).copied().unwrap_or_else(|| {
            let (x, y) = (p[a as usize], p[b as usize]);
            (0.5 * (x.0 + y.0), 0.5 * (x.1 + y.1))
        }),
        Node::Centroid(t) => {
            let corners = match lattice.charts.as_ref().and_then(|c| c.get(t as usize)) {
                Some(ch) => *ch,
                None => lattice.triangles[t as usize].map(|v| p[v as usize]),
            };
            let s = corners
                .iter()
                .fold((0.0, 0.0), |s, c| (s.0 + c.0, s.1 + c.1));
            (s.0 / 3.0, s.1 / 3.0)
        }
    }
}

fn node_order(n: Node) -> (u8, u32, u32) {
    match n {
        Node::Vertex(v) => (0, v, 0),
        Node::Mid(a, b) => (1, a, b),
        Node::Centroid(t) => (2, t, 0),
    }
}

/// The directed edges of a closed vertex loop.
fn loop_edges(l: &[u32]) -> Vec<(u32, u32)> {
    (0..l.len()).map(|e| (l[e], l[(e + 1) % l.len()])).collect()
}
