//! Unsigned distance from points to a triangle mesh: closest point on each nearby triangle,
//! triangles bucketed in a uniform grid by their bounding boxes. Used to measure how far a
//! fitted surface strays from the data (one-sided, surface to data).

use super::TriMesh;
use glam::DVec3;
use rustc_hash::FxHashMap;

/// Closest-point queries against a triangle mesh through a uniform grid of buckets.
pub struct MeshDistance<'a> {
    mesh: &'a TriMesh,
    mean_edge: f64,
    cell: f64,
    buckets: FxHashMap<(i64, i64, i64), Vec<u32>>,
    /// The lowest and highest cell keys holding a triangle (per axis).
    occupied: [(i64, i64, i64); 2],
}

impl<'a> MeshDistance<'a> {
    /// Buckets the triangles of `mesh` (cells two mean edges wide).
    pub fn new(mesh: &'a TriMesh) -> Self {
        let p = &mesh.positions;
        let mean_edge = mesh
            .triangles
            .iter()
            .map(|t| (p[t[0] as usize] - p[t[1] as usize]).length())
            .sum::<f64>()
            / mesh.triangles.len().max(1) as f64;
        let cell = (2.0 * mean_edge).max(1e-12);
        let mut buckets: FxHashMap<(i64, i64, i64), Vec<u32>> = FxHashMap::default();
        let mut occupied = [
            (i64::MAX, i64::MAX, i64::MAX),
            (i64::MIN, i64::MIN, i64::MIN),
        ];
        for (f, t) in mesh.triangles.iter().enumerate() {
            let pts = t.map(|v| p[v as usize]);
            let lo = pts[0].min(pts[1]).min(pts[2]);
            let hi = pts[0].max(pts[1]).max(pts[2]);
            let (a, b) = (Self::key(cell, lo), Self::key(cell, hi));
            occupied[0] = (
                occupied[0].0.min(a.0),
                occupied[0].1.min(a.1),
                occupied[0].2.min(a.2),
            );
            occupied[1] = (
                occupied[1].0.max(b.0),
                occupied[1].1.max(b.1),
                occupied[1].2.max(b.2),
            );
            for x in a.0..=b.0 {
                for y in a.1..=b.1 {
                    for z in a.2..=b.2 {
                        buckets.entry((x, y, z)).or_default().push(f as u32);
                    }
                }
            }
        }
        Self {
            mesh,
            mean_edge,
            cell,
            buckets,
            occupied,
        }
    }

    /// The mesh's mean edge length (over each triangle's first edge).
    pub fn mean_edge(&self) -> f64 {
        self.mean_edge
    }

    fn key(cell: f64, p: DVec3) -> (i64, i64, i64) {
        let q = (p / cell).floor();
        (q.x as i64, q.y as i64, q.z as i64)
    }

    /// Distance to the nearest triangle, or `None` for an empty mesh or non-finite point.
    pub fn distance(&self, q: DVec3) -> Option<f64> {
        self.closest(q).map(|c| (c.point - q).length())
    }

    /// The nearest point of the mesh to `q` and its triangle, or `None` for an empty mesh
    /// or non-finite point.
    pub fn closest(&self, q: DVec3) -> Option<Closest> {
        self.closest_near(q, None)
    }

    /// [`closest`](Self::closest), starting from the distance to triangle `hint` (the
    /// nearest triangle of a query close to `q`, such as the previous sample of a lattice):
    /// the cells no nearer than that are skipped, and where it is within `q`'s margin in
    /// its own cell the search ends there. The same distance as without a hint.
    pub fn closest_near(&self, q: DVec3, hint: Option<u32>) -> Option<Closest> {
        if self.mesh.triangles.is_empty() || !q.is_finite() {
            return None;
        }
        let c = Self::key(self.cell, q);
        // Where q lies in its cell: the block of cells within r of it holds the ball of
        // radius r cells plus the smallest of these around q.
        let inside = q / self.cell - (q / self.cell).floor();
        let margin = inside.min(DVec3::ONE - inside).min_element() * self.cell;
        let mut best = hint
            .and_then(|f| Some((f, self.mesh.triangles.get(f as usize)?)))
            .map(|(f, t)| {
                let p = &self.mesh.positions;
                let point =
                    closest_on_triangle(q, p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
                ((point - q).length(), Closest { point, triangle: f })
            });
        // Only the shells that meet the occupied cells are searched, and only where they
        // meet them: a query far off the mesh (a surface point a diverged fit threw away)
        // costs the occupied block, not every empty cell between it and the mesh.
        let [lo, hi] = self.occupied;
        let gap = |c: i64, lo: i64, hi: i64| lo.saturating_sub(c).max(c.saturating_sub(hi)).max(0);
        let reach = |c: i64, lo: i64, hi: i64| c.saturating_sub(lo).max(hi.saturating_sub(c));
        let first = gap(c.0, lo.0, hi.0)
            .max(gap(c.1, lo.1, hi.1))
            .max(gap(c.2, lo.2, hi.2));
        let last = reach(c.0, lo.0, hi.0)
            .max(reach(c.1, lo.1, hi.1))
            .max(reach(c.2, lo.2, hi.2));
        for r in first..=last {
            for cell in shell_within(c, r, self.occupied) {
                // A cell no nearer than the best point found holds no nearer point (a
                // triangle is in every cell its box meets, so in the cell of its point
                // nearest q): most queries of a surface near its data end in the first
                // cell and a few of its 26 neighbours.
                let reached = best.as_ref().map_or(f64::INFINITY, |(d, _)| *d);
                if self.gap_to_cell(q, cell) > reached * (1.0 + 1e-9) {
                    continue;
                }
                let Some(faces) = self.buckets.get(&cell) else {
                    continue;
                };
                for &f in faces {
                    let t = self.mesh.triangles[f as usize];
                    let p = &self.mesh.positions;
                    let point = closest_on_triangle(
                        q,
                        p[t[0] as usize],
                        p[t[1] as usize],
                        p[t[2] as usize],
                    );
                    let d = (point - q).length();
                    if best.as_ref().is_none_or(|(b, _)| d < *b) {
                        best = Some((d, Closest { point, triangle: f }));
                    }
                }
            }
            // Every triangle with a point nearer than the block's margin has that point,
            // and so its bounding box, in a searched cell: no farther shell can beat it.
            let reached = best.as_ref().map_or(f64::MAX, |(d, _)| *d);
            if reached <= r as f64 * self.cell + margin {
                break;
            }
        }
        if best.is_none() {
            // Cell keys saturate for queries beyond i64 cells (1e150 m): every triangle then.
            best = (0..self.mesh.triangles.len() as u32)
                .map(|f| {
                    let t =
                        self.mesh.triangles[f as usize].map(|v| self.mesh.positions[v as usize]);
                    let point = closest_on_triangle(q, t[0], t[1], t[2]);
                    ((point - q).length(), Closest { point, triangle: f })
                })
                .min_by(|a, b| a.0.total_cmp(&b.0));
        }
        best.map(|(_, c)| c)
    }
}

impl MeshDistance<'_> {
    /// Distance from `q` to the box of `cell`.
    fn gap_to_cell(&self, q: DVec3, cell: (i64, i64, i64)) -> f64 {
        let lo = DVec3::new(cell.0 as f64, cell.1 as f64, cell.2 as f64) * self.cell;
        let hi = lo + DVec3::splat(self.cell);
        (lo - q).max(q - hi).max(DVec3::ZERO).length()
    }
}

/// The cells at Chebyshev distance exactly `r` from `c` (only `c` for r = 0) inside the
/// block `within` (lowest and highest key per axis).
fn shell_within(
    c: (i64, i64, i64),
    r: i64,
    within: [(i64, i64, i64); 2],
) -> impl Iterator<Item = (i64, i64, i64)> {
    let [lo, hi] = within;
    let span =
        move |c: i64, lo: i64, hi: i64| lo.max(c.saturating_sub(r))..=hi.min(c.saturating_add(r));
    let on_shell = move |v: i64, c: i64| v.abs_diff(c) == r as u64;
    span(c.0, lo.0, hi.0).flat_map(move |x| {
        span(c.1, lo.1, hi.1).flat_map(move |y| {
            // On a face of the block in x or y every z is on the shell; inside, only the
            // two z faces are.
            let full = on_shell(x, c.0) || on_shell(y, c.1);
            let dense = span(c.2, lo.2, hi.2).take(if full { usize::MAX } else { 0 });
            // (Not full only for r > 0: at r = 0 the one column is c's own.)
            let faces = [c.2.saturating_sub(r), c.2.saturating_add(r)]
                .into_iter()
                .filter(move |z| !full && (lo.2..=hi.2).contains(z));
            dense.chain(faces).map(move |z| (x, y, z))
        })
    })
}

/// The nearest point of a mesh to a query.
#[derive(Clone, Copy, Debug)]
pub struct Closest {
    /// The point itself.
    pub point: DVec3,
    /// Index of the triangle it lies on.
    pub triangle: u32,
}

/// Closest point of triangle abc to p (Voronoi regions of vertices, edges, face).
pub(crate) fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom == 0.0 {
        return a;
    }
    a + ab * (vb / denom) + ac * (vc / denom)
}

/// Squared distance from `p` to triangle `tri` and the barycentric weights of the
/// closest point.
pub(crate) fn project_onto_triangle(p: DVec3, tri: [DVec3; 3]) -> (f64, [f64; 3]) {
    let q = closest_on_triangle(p, tri[0], tri[1], tri[2]);
    ((q - p).length_squared(), barycentric_on(q, tri))
}

/// The barycentric weights of `q`, a point on triangle `tri`, clamped to the triangle.
pub(crate) fn barycentric_on(q: DVec3, tri: [DVec3; 3]) -> [f64; 3] {
    let (e0, e1, e2) = (tri[1] - tri[0], tri[2] - tri[0], q - tri[0]);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (e2.dot(e0), e2.dot(e1));
    let denom = d00 * d11 - d01 * d01;
    if denom > 0.0 {
        let b1 = ((d11 * d20 - d01 * d21) / denom).clamp(0.0, 1.0);
        let b2 = ((d00 * d21 - d01 * d20) / denom).clamp(0.0, 1.0 - b1);
        [1.0 - b1 - b2, b1, b2]
    } else {
        [1.0, 0.0, 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_to_a_grid_match_brute_force() {
        let n = 12;
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                positions.push(DVec3::new(x, y, 0.2 * (3.0 * x).sin() * y));
            }
        }
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let mesh = TriMesh::new(positions, triangles);
        let md = MeshDistance::new(&mesh);
        // Far points (many shells searched) and points just off the surface (the search
        // ends in the first cells, by the margin of the query inside its cell).
        let far = (0..200).map(|k| {
            let t = k as f64 * 0.37;
            DVec3::new(1.4 * t.sin(), 1.3 * (0.7 * t).cos(), 0.5 * (1.3 * t).sin())
        });
        let near = (0..200).map(|k| {
            let (x, y) = ((k as f64 * 0.618).fract(), (k as f64 * 0.414).fract());
            DVec3::new(x, y, 0.2 * (3.0 * x).sin() * y + 0.004 * (k as f64).cos())
        });
        for q in far.chain(near) {
            let brute = mesh
                .triangles
                .iter()
                .map(|t| {
                    let p = &mesh.positions;
                    (closest_on_triangle(q, p[t[0] as usize], p[t[1] as usize], p[t[2] as usize])
                        - q)
                        .length()
                })
                .fold(f64::MAX, f64::min);
            let got = md.distance(q).expect("non-empty");
            assert!((got - brute).abs() < 1e-12, "{q}: {got} vs {brute}");
            // The closest point is the one of the triangle it names.
            let c = md.closest(q).expect("non-empty");
            let t = mesh.triangles[c.triangle as usize].map(|v| mesh.positions[v as usize]);
            let on = closest_on_triangle(q, t[0], t[1], t[2]);
            assert!(on.distance(c.point) < 1e-12, "{q}: {on} vs {}", c.point);
            // Any hint (the answer, a far triangle, one past the mesh) gives the same
            // distance.
            for hint in [c.triangle, 0, mesh.triangles.len() as u32 - 1, u32::MAX] {
                let near = md.closest_near(q, Some(hint)).expect("non-empty");
                let d = (near.point - q).length();
                assert!((d - brute).abs() < 1e-12, "{q} from {hint}: {d} vs {brute}");
            }
        }
    }

    #[test]
    fn a_query_far_off_the_mesh_is_answered_at_the_cost_of_the_mesh() {
        // Millions of empty cells lie between these points and the two-triangle square:
        // the search visits only the cells that hold triangles.
        let mesh = TriMesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.0)],
            vec![[0, 1, 2], [1, 3, 2]],
        );
        let md = MeshDistance::new(&mesh);
        for (q, want) in [
            (DVec3::new(0.5, 0.5, 3e6), 3e6),
            (DVec3::new(-4e6, 0.5, 0.0), 4e6),
            (DVec3::new(1.0, 1.0, -1e150), 1e150),
        ] {
            let got = md.distance(q).expect("a finite query has a distance");
            assert!(
                (got - want).abs() <= 1e-9 * want,
                "{q}: {got} against {want}"
            );
        }
    }
}
