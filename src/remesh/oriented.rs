//! Oriented normals of an unorganised point cloud (Hoppe et al. 1992, "Surface
//! reconstruction from unorganized points"): each point's normal is the direction of least
//! variance of its nearest neighbours (a local plane fit), and the signs are made
//! consistent by walking a minimum spanning tree of the neighbour graph whose edge cost is
//! `1 - |n_i . n_j|`, so that the walk crosses between nearly parallel planes first and
//! reaches a sharp bend or a thin part last. Each connected piece starts at its highest
//! point (largest z), whose normal is turned to +z: on a closed surface that point's
//! outward normal points up.
//!
//! Written here rather than taken from a crate: no maintained Rust crate estimates and
//! orients normals (Open3D and PCL, which do, are C++).

use glam::DVec3;
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;

/// Neighbours of a point for its plane fit and its edges in the orientation graph, on
/// clean data.
pub const NORMAL_NEIGHBOURS: usize = 12;

/// Most neighbours a plane fit takes on noisy data.
const MAX_NORMAL_NEIGHBOURS: usize = 128;

/// Neighbours over which the noise is measured: their radius, about 4 spacings, spans
/// noise as large as the spacing. The 12 nearest are no measure of such noise: the
/// nearest points in space are those displaced alike (on the sphere of CGAL's
/// `sphere_20k.xyz`, radial noise 0.041, they measured 0.017).
const NOISE_NEIGHBOURS: usize = 48;

/// Points the noise and the spacing (two medians) are measured at, at most: every
/// n / `MEASURED_POINTS`-th point, so that a million-point cloud does not find 48
/// neighbours for each.
const MEASURED_POINTS: usize = 20_000;

/// Most neighbour entries kept for the plane fits and the orientation graph (4 bytes
/// each, and as many again for the graph's reverse edges): on a large noisy cloud the
/// neighbours per point give way to it rather than memory.
const MAX_NEIGHBOUR_ENTRIES: usize = 32_000_000;

/// Neighbours whose mean distance is a point's local spacing (as `points` measures it).
const SPACING_NEIGHBOURS: usize = 6;

/// The quantile of the local spacings the width covers. The merge defines a surface only
/// within a few cells of the points, so a width from the median spacing leaves holes
/// wherever the points are sparser than usual (mesh vertices of adaptive density, a
/// scan's grazing parts); the 90th percentile covers all but the sparsest tenth (CGAL's
/// kitten.xyz: 2 holes at the median, none at it; camel.off's vertices as a cloud: RMS
/// to the surface 0.18 at the median, most of its legs missing, 0.031 at it).
const SPARSE_SPACING_QUANTILE: f64 = 0.9;

/// The smoothing width on clean data, in spacings: a range scan's merge cell (1.5 of its
/// median edge, about one spacing).
pub const CLEAN_WIDTH_SPACINGS: f64 = 1.5;

/// The noise a Gaussian average of width h may leave, as a share of h. Averaging the
/// k = pi (h / s)^2 points within h (spacing s) divides the noise sigma by sqrt(k), so
/// sigma s / (sqrt(pi) h) <= `AVERAGED_NOISE_SHARE` h sets the width.
const AVERAGED_NOISE_SHARE: f64 = 0.1;

/// A cloud's oriented normals and its sampling density and noise.
#[derive(Clone, Debug)]
pub struct OrientedNormals {
    /// One unit normal per point, consistently signed within each connected piece
    /// (zero for a point whose neighbours do not span a plane).
    pub normals: Vec<DVec3>,
    /// Median over the points of their mean distance to their 6 nearest others.
    pub spacing: f64,
    /// Median over the points of the RMS distance of them and their 48 nearest neighbours
    /// to their least-squares plane: the scanner's noise (and, on clean data, the
    /// curvature's sag over about 4 spacings).
    pub noise: f64,
    /// The 90th percentile of the points' local spacing (`SPARSE_SPACING_QUANTILE`).
    pub sparse_spacing: f64,
    /// The width over which the points must be averaged for a surface: `sparse_spacing`
    /// times `CLEAN_WIDTH_SPACINGS`, or more where the noise asks for it (see
    /// `AVERAGED_NOISE_SHARE`).
    pub width: f64,
    /// Neighbours each normal was fitted to: more than `NORMAL_NEIGHBOURS` on noisy data
    /// (in proportion to the area the noise's width covers), fewer on clouds of millions of
    /// points (`MAX_NEIGHBOUR_ENTRIES`).
    pub neighbours: usize,
    /// Connected pieces of the neighbour graph, each oriented on its own.
    pub pieces: usize,
    /// Tree edges crossed between normals more than 60 degrees apart: where the
    /// orientation had to guess (sharp edges, thin parts, noise).
    pub sharp_crossings: usize,
}

type Indexed = GeomWithData<[f64; 3], u32>;

/// Estimates and orients the normals of `points` (see the module docs). Non-finite
/// points get a zero normal and no edges. On noisy data (noise comparable with the
/// spacing) the plane fits take as many more neighbours as the width the noise needs
/// covers, so that a normal is not tilted by the noise of a few points.
pub fn oriented_normals(points: &[DVec3]) -> OrientedNormals {
    let tree: RTree<Indexed> = RTree::bulk_load(
        points
            .iter()
            .enumerate()
            .filter(|(_, p)| p.is_finite())
            .map(|(i, p)| Indexed::new(p.to_array(), i as u32))
            .collect(),
    );
    let stride = points.len().div_ceil(MEASURED_POINTS).max(1);
    let measured: Vec<u32> = (0..points.len() as u32).step_by(stride).collect();
    let wide = Neighbours::find(points, &tree, &measured, NOISE_NEIGHBOURS);
    let spacings = local_spacings(points, &measured, &wide);
    let spacing = quantile(spacings.clone(), 0.5);
    let sparse = quantile(spacings, SPARSE_SPACING_QUANTILE);
    let noise = median(
        plane_fits(points, &measured, &wide)
            .iter()
            .filter(|p| p.normal != DVec3::ZERO)
            .map(|p| p.residual),
    );
    let typical_width = CLEAN_WIDTH_SPACINGS * spacing;
    let noisy_width =
        (noise * spacing / (AVERAGED_NOISE_SHARE * std::f64::consts::PI.sqrt())).sqrt();
    let width = (CLEAN_WIDTH_SPACINGS * sparse).max(noisy_width);
    let most = (MAX_NEIGHBOUR_ENTRIES / points.len().max(1)).max(3);
    // The plane fits widen with the noise alone: a sparse part of the cloud needs no
    // more neighbours to span its plane.
    let k = if typical_width > 0.0 {
        ((NORMAL_NEIGHBOURS as f64 * (noisy_width / typical_width).powi(2)).ceil() as usize)
            .clamp(NORMAL_NEIGHBOURS, MAX_NORMAL_NEIGHBOURS)
    } else {
        NORMAL_NEIGHBOURS
    }
    .min(most);
    let all: Vec<u32> = (0..points.len() as u32).collect();
    let near = Neighbours::find(points, &tree, &all, k);
    let mut normals: Vec<DVec3> = plane_fits(points, &all, &near)
        .into_iter()
        .map(|p| p.normal)
        .collect();
    let (pieces, sharp_crossings) = orient(points, &near, &mut normals);
    OrientedNormals {
        normals,
        spacing,
        sparse_spacing: sparse,
        noise,
        width,
        neighbours: k,
        pieces,
        sharp_crossings,
    }
}

/// The `k` nearest other points of some points, `k` entries each (`u32::MAX` past the
/// last where a point has fewer), in one allocation.
struct Neighbours {
    k: usize,
    ids: Vec<u32>,
}

impl Neighbours {
    /// The neighbours of `of` (indices into `points`), in that order; none for a point
    /// that is not finite.
    fn find(points: &[DVec3], tree: &RTree<Indexed>, of: &[u32], k: usize) -> Self {
        let mut ids = vec![u32::MAX; of.len() * k];
        ids.par_chunks_mut(k.max(1))
            .zip(of.par_iter())
            .for_each(|(slot, &i)| {
                let p = points[i as usize];
                if !p.is_finite() {
                    return;
                }
                let found = tree
                    .nearest_neighbor_iter(&p.to_array())
                    .map(|n| n.data)
                    .filter(|&j| j != i)
                    .take(k);
                for (s, j) in slot.iter_mut().zip(found) {
                    *s = j;
                }
            });
        Self { k, ids }
    }

    /// The neighbours of the `r`-th point asked for.
    fn of(&self, r: usize) -> &[u32] {
        let row = &self.ids[r * self.k..(r + 1) * self.k];
        let len = row.iter().position(|&j| j == u32::MAX).unwrap_or(self.k);
        &row[..len]
    }
}

/// A point's least-squares plane through it and its neighbours.
struct PlaneFit {
    /// Unit normal (zero where they span no plane).
    normal: DVec3,
    /// RMS distance of the points to the plane.
    residual: f64,
}

/// The plane of each point of `of` through it and its neighbours `near`.
fn plane_fits(points: &[DVec3], of: &[u32], near: &Neighbours) -> Vec<PlaneFit> {
    of.par_iter()
        .enumerate()
        .map(|(r, &i)| {
            let around = near.of(r).iter().map(|&j| points[j as usize]);
            plane_fit(points[i as usize], around)
        })
        .collect()
}

/// The least-squares plane through `p` and `near`: its normal is the eigenvector of the
/// smallest eigenvalue of their covariance (zero where they span no plane), whose mean is
/// the squared residual.
fn plane_fit(p: DVec3, near: impl Iterator<Item = DVec3> + Clone) -> PlaneFit {
    let none = PlaneFit {
        normal: DVec3::ZERO,
        residual: 0.0,
    };
    let count = 1 + near.clone().count();
    if count < 3 {
        return none;
    }
    let centre = (p + near.clone().sum::<DVec3>()) / count as f64;
    let ([largest, middle, smallest], axes) =
        crate::numeric::principal_axes(centre, std::iter::once(p).chain(near));
    // A plane needs two directions of spread: the middle eigenvalue must not vanish.
    if largest.is_nan() || middle.is_nan() || middle <= 1e-12 * largest {
        return none;
    }
    match axes[2].try_normalize() {
        Some(normal) => PlaneFit {
            normal,
            residual: (smallest.max(0.0) / count as f64).sqrt(),
        },
        None => none,
    }
}

/// Median over the points of `of` of their mean distance to their nearest
/// `SPACING_NEIGHBOURS`.
fn local_spacings(points: &[DVec3], of: &[u32], near: &Neighbours) -> Vec<f64> {
    of.iter()
        .enumerate()
        .filter_map(|(r, &i)| {
            let near = near.of(r);
            let k = near.len().min(SPACING_NEIGHBOURS);
            let p = points[i as usize];
            (k > 0).then(|| {
                near[..k]
                    .iter()
                    .map(|&j| p.distance(points[j as usize]))
                    .sum::<f64>()
                    / k as f64
            })
        })
        .collect()
}

/// The median of `values` (0 when there are none).
fn median(values: impl Iterator<Item = f64>) -> f64 {
    quantile(values.collect(), 0.5)
}

/// The `q` quantile of `v` (0 when it is empty).
fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}

/// Cosine below which a tree edge counts as a sharp crossing (60 degrees).
const SHARP_COS: f64 = 0.5;

/// Signs the normals consistently along a minimum spanning tree of the symmetric neighbour
/// graph (Prim's algorithm, cost `1 - |n_i . n_j|`), one tree per connected piece rooted
/// at its highest point with its normal turned up. Returns the pieces and the sharp
/// crossings.
fn orient(points: &[DVec3], near: &Neighbours, normals: &mut [DVec3]) -> (usize, usize) {
    let n = points.len();
    let adjacency = Graph::symmetric(n, near);
    let mut by_height: Vec<u32> = (0..n as u32)
        .filter(|&i| normals[i as usize] != DVec3::ZERO)
        .collect();
    by_height.sort_by(|&a, &b| points[b as usize].z.total_cmp(&points[a as usize].z));
    let mut reached = vec![false; n];
    let (mut pieces, mut sharp) = (0, 0);
    let mut heap = CostQueue::default();
    for &root in &by_height {
        if reached[root as usize] {
            continue;
        }
        pieces += 1;
        reached[root as usize] = true;
        if normals[root as usize].z < 0.0 {
            normals[root as usize] = -normals[root as usize];
        }
        push_edges(root, &adjacency, normals, &reached, &mut heap);
        while let Some((from, to)) = heap.pop() {
            let (f, t) = (from as usize, to as usize);
            if reached[t] {
                continue;
            }
            reached[t] = true;
            let cos = normals[f].dot(normals[t]);
            if cos < 0.0 {
                normals[t] = -normals[t];
            }
            if cos.abs() < SHARP_COS {
                sharp += 1;
            }
            push_edges(to, &adjacency, normals, &reached, &mut heap);
        }
    }
    (pieces, sharp)
}

/// The symmetric neighbour graph in compressed rows: each point's neighbours and the
/// points it is a neighbour of (an edge found both ways appears twice, which Prim's
/// algorithm takes as it comes).
struct Graph {
    start: Vec<usize>,
    to: Vec<u32>,
}

impl Graph {
    /// The graph of the neighbours of all `n` points (`near` found for every point).
    fn symmetric(n: usize, near: &Neighbours) -> Self {
        let mut degree = vec![0usize; n + 1];
        for i in 0..n {
            for &j in near.of(i) {
                degree[i] += 1;
                degree[j as usize] += 1;
            }
        }
        let mut start = Vec::with_capacity(n + 1);
        let mut total = 0;
        for d in &degree[..n] {
            start.push(total);
            total += d;
        }
        start.push(total);
        let mut fill = start.clone();
        let mut to = vec![0u32; total];
        for i in 0..n {
            for &j in near.of(i) {
                to[fill[i]] = j;
                fill[i] += 1;
                to[fill[j as usize]] = i as u32;
                fill[j as usize] += 1;
            }
        }
        Self { start, to }
    }

    fn of(&self, i: usize) -> &[u32] {
        &self.to[self.start[i]..self.start[i + 1]]
    }
}

/// Queues the edges from `from` to the unreached neighbours that have a normal.
fn push_edges(
    from: u32,
    adjacency: &Graph,
    normals: &[DVec3],
    reached: &[bool],
    heap: &mut CostQueue,
) {
    let nf = normals[from as usize];
    for &to in adjacency.of(from as usize) {
        let nt = normals[to as usize];
        if reached[to as usize] || nt == DVec3::ZERO {
            continue;
        }
        heap.push(1.0 - nf.dot(nt).abs(), from, to);
    }
}

/// Levels the costs in [0, 1] are sorted into.
const COST_LEVELS: usize = 1024;

/// Prim's queue of edges by cost, the costs `1 - |cos|` in [0, 1] sorted into
/// `COST_LEVELS` levels: pushing and taking cost the same at any size, where a binary heap
/// of a million-point cloud's 24 million edges took most of the orientation's time. Edges
/// of one level (normals within a tenth of a degree near parallel) come in any order:
/// the tree is minimal to within the level's width.
#[derive(Default)]
struct CostQueue {
    levels: Vec<Vec<(u32, u32)>>,
    lowest: usize,
}

impl CostQueue {
    fn push(&mut self, cost: f64, from: u32, to: u32) {
        if self.levels.is_empty() {
            self.levels = vec![Vec::new(); COST_LEVELS];
        }
        let level = ((cost.clamp(0.0, 1.0) * (COST_LEVELS - 1) as f64).round() as usize)
            .min(COST_LEVELS - 1);
        self.levels[level].push((from, to));
        self.lowest = self.lowest.min(level);
    }

    fn pop(&mut self) -> Option<(u32, u32)> {
        while self.lowest < self.levels.len() {
            if let Some(edge) = self.levels[self.lowest].pop() {
                return Some(edge);
            }
            self.lowest += 1;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a torus (radii `big`, `small`), `n` x `m` on a jittered lattice.
    fn torus_points(n: usize, m: usize, big: f64, small: f64) -> Vec<DVec3> {
        let mut points = Vec::new();
        for i in 0..n {
            for j in 0..m {
                // A deterministic jitter so that the samples are not a lattice.
                let ju = ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.5;
                let jv = ((i * 5 + j * 3) % 7) as f64 / 7.0 - 0.5;
                let u = (i as f64 + 0.4 * ju) / n as f64 * std::f64::consts::TAU;
                let v = (j as f64 + 0.4 * jv) / m as f64 * std::f64::consts::TAU;
                let r = big + small * v.cos();
                points.push(DVec3::new(r * u.cos(), r * u.sin(), small * v.sin()));
            }
        }
        points
    }

    #[test]
    fn a_torus_cloud_gets_outward_normals_everywhere() {
        let (big, small) = (1.0, 0.35);
        let points = torus_points(120, 48, big, small);
        let oriented = oriented_normals(&points);
        assert_eq!(oriented.pieces, 1);
        let mut wrong = 0;
        for (p, n) in points.iter().zip(&oriented.normals) {
            // The outward normal points from the tube's core circle to the point.
            let core = DVec3::new(p.x, p.y, 0.0).normalize() * big;
            let outward = (*p - core).normalize();
            assert!(n.length() > 0.99, "a unit normal at {p}");
            if n.dot(outward) < 0.9 {
                wrong += 1;
            }
        }
        assert_eq!(wrong, 0, "{wrong} of {} normals not outward", points.len());
        // The mean 6-NN distance of a lattice of these steps lies between its two steps.
        let (step_u, step_v) = (
            std::f64::consts::TAU * (big - small) / 120.0,
            std::f64::consts::TAU * small / 48.0,
        );
        assert!(oriented.spacing > 0.5 * step_u.min(step_v));
        assert!(oriented.spacing < 2.0 * std::f64::consts::TAU * (big + small) / 120.0);
    }

    #[test]
    fn separate_pieces_are_each_oriented_up_from_their_top() {
        let mut points = torus_points(60, 24, 1.0, 0.35);
        let far: Vec<DVec3> = torus_points(60, 24, 1.0, 0.35)
            .into_iter()
            .map(|p| p + DVec3::new(10.0, 0.0, 0.0))
            .collect();
        points.extend(far);
        let oriented = oriented_normals(&points);
        assert_eq!(oriented.pieces, 2);
        for (k, (p, n)) in points.iter().zip(&oriented.normals).enumerate() {
            let centre = if k < 60 * 24 {
                DVec3::ZERO
            } else {
                DVec3::new(10.0, 0.0, 0.0)
            };
            let q = *p - centre;
            let core = DVec3::new(q.x, q.y, 0.0).normalize();
            assert!(n.dot((q - core).normalize()) > 0.8, "point {k}");
        }
    }

    #[test]
    fn collinear_and_lone_points_get_no_normal() {
        let mut points: Vec<DVec3> = (0..20).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
        points.push(DVec3::new(f64::NAN, 0.0, 0.0));
        let oriented = oriented_normals(&points);
        assert!(oriented.normals.iter().all(|n| *n == DVec3::ZERO));
        assert_eq!(oriented.pieces, 0);
    }
}
