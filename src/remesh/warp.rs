//! A smooth, globally injective warp of a scan's projection plane that evens out the
//! projection's stretch.
//!
//! The line-of-sight projection squeezes surface seen at grazing angles: there a unit of
//! plane holds up to ~3x more surface, so the regular control grid laid over the plane is
//! ~3x sparser on the surface exactly where the shape bends away from the scanner. The
//! warp is an as-rigid-as-possible map (Liu et al. 2008, local/global) of a coarse
//! equilateral lattice over the plane, whose triangles aim at the surface's metric averaged
//! over them (data triangles' first fundamental forms); lattice triangles without data aim
//! at their own shape. Working on the coarse lattice instead of the scan's own triangles
//! keeps the scan noise out of the map and makes it cheap.
//!
//! Injectivity: a piecewise-linear map of a triangulated disk that keeps every triangle's
//! orientation and maps the boundary to a simple closed curve is one-to-one. Both are
//! checked; failing that, the warp is blended toward the identity until they hold.

use super::band::BandMatrix;
use super::plane2d::{doubled_area, simple_polygon};
use crate::numeric::floor;
use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

const SQRT3_2: f64 = 0.866_025_403_784_438_6;

/// Data triangles per parallel task of the metric sums.
const METRIC_CHUNK: usize = 16_384;

/// The most a lattice triangle is stretched toward the surface's size, per direction. The
/// line of sight meets grazing walls and silhouettes at stretches of 3-5 and more; there the
/// scanner's samples are sparse, and giving such a wall its full size would spend control
/// points on gaps between samples, where the surface is then free to bulge (measured on the
/// Stanford scans: tessellation-to-data distances of 1.1-2.2 mm uncapped, under 0.9 mm
/// capped at 2).
const MAX_DIRECTIONAL_STRETCH: f64 = 2.0;

/// A piecewise-linear map of the plane given by the images of an equilateral lattice's
/// vertices; the identity outside the lattice (never reached by the points it was built for).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlaneWarp {
    origin: DVec2,
    spacing: f64,
    /// Lattice vertices per row and rows (vertex (i, j) at `i + j * columns`).
    columns: usize,
    rows: usize,
    image: Vec<DVec2>,
    /// How much of the relaxed warp is kept (1: all of it; less where it had to be blended
    /// toward the identity to stay one-to-one).
    pub blend: f64,
}

impl PlaneWarp {
    /// The warp for `plane` (map positions of `positions`, the data triangles `tris`), with
    /// about `lattice_triangles` lattice triangles over the data. `None` when the data
    /// gives nothing to even out (no triangle of positive area).
    pub fn build(
        positions: &[DVec3],
        plane: &[DVec2],
        tris: &[[u32; 3]],
        lattice_triangles: usize,
        iterations: usize,
    ) -> Option<Self> {
        let area: f64 = tris
            .iter()
            .map(|t| 0.5 * doubled_area(plane, t).max(0.0))
            .sum();
        if area.is_nan() || area <= 0.0 || lattice_triangles == 0 {
            return None;
        }
        let spacing = (4.0 * area / (3f64.sqrt() * lattice_triangles as f64)).sqrt();
        let (mut lo, mut hi) = (DVec2::splat(f64::MAX), DVec2::splat(f64::MIN));
        for t in tris {
            for &v in t {
                lo = lo.min(plane[v as usize]);
                hi = hi.max(plane[v as usize]);
            }
        }
        // A parallelogram of lattice cells around the bounding box with one cell to spare.
        let to_lattice = |p: DVec2| {
            let y = p.y / (spacing * SQRT3_2);
            DVec2::new(p.x / spacing - 0.5 * y, y)
        };
        let corners = [lo, hi, DVec2::new(lo.x, hi.y), DVec2::new(hi.x, lo.y)].map(to_lattice);
        let (mut glo, mut ghi) = (corners[0], corners[0]);
        for c in corners {
            glo = glo.min(c);
            ghi = ghi.max(c);
        }
        let (i0, j0) = (glo.x.floor() - 1.0, glo.y.floor() - 1.0);
        let columns = (ghi.x.ceil() + 1.0 - i0) as usize + 1;
        let rows = (ghi.y.ceil() + 1.0 - j0) as usize + 1;
        if columns.saturating_mul(rows) > 4 * lattice_triangles + 10_000 {
            // A sliver-shaped bounding box would waste most of the lattice: not worth it.
            return None;
        }
        let origin = DVec2::new(spacing * (i0 + 0.5 * j0), spacing * SQRT3_2 * j0);
        let identity = Self {
            origin,
            spacing,
            columns,
            rows,
            image: Vec::new(),
            blend: 1.0,
        };
        let rest = identity.vertex_positions();
        let metrics = identity.average_metrics(positions, plane, tris);
        let image = relax(&identity, &rest, &metrics, iterations)?;
        let warp = Self { image, ..identity };
        warp.made_injective(&rest)
    }

    /// Whether the warp is well formed (one read back from a state file may not be) and
    /// every point lies inside its lattice, where it is what it was built as.
    pub fn covers(&self, points: &[DVec2]) -> bool {
        let well_formed = self.columns >= 2
            && self.rows >= 2
            && self.columns.checked_mul(self.rows) == Some(self.image.len())
            && self.spacing.is_finite()
            && self.spacing > 0.0
            && self.origin.is_finite()
            && self.image.iter().all(|p| p.is_finite());
        well_formed && points.iter().all(|p| self.locate(*p).is_some())
    }

    /// Where the lattice puts point `p`.
    pub fn apply(&self, p: DVec2) -> DVec2 {
        match self.locate(p) {
            Some((c, b)) => {
                let v = self.triangle(c);
                self.image[v[0]] * b[0] + self.image[v[1]] * b[1] + self.image[v[2]] * b[2]
            }
            None => p,
        }
    }

    fn vertex_positions(&self) -> Vec<DVec2> {
        let mut out = Vec::with_capacity(self.columns * self.rows);
        for j in 0..self.rows {
            for i in 0..self.columns {
                let (x, y) = (i as f64, j as f64);
                out.push(self.origin + self.spacing * DVec2::new(x + 0.5 * y, SQRT3_2 * y));
            }
        }
        out
    }

    fn cell_count(&self) -> usize {
        2 * (self.columns - 1) * (self.rows - 1)
    }

    /// Lattice triangle `c` as vertex indices, counter-clockwise: cells by row, each as its
    /// upward then its downward triangle.
    fn triangle(&self, c: usize) -> [usize; 3] {
        let (cell, down) = (c / 2, c % 2 == 1);
        let (i, j) = (cell % (self.columns - 1), cell / (self.columns - 1));
        let v = |i: usize, j: usize| i + j * self.columns;
        if down {
            [v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]
        } else {
            [v(i, j), v(i + 1, j), v(i, j + 1)]
        }
    }

    /// The lattice triangle holding `p` and `p`'s barycentric coordinates in it.
    fn locate(&self, p: DVec2) -> Option<(usize, [f64; 3])> {
        let d = p - self.origin;
        let y = d.y / (self.spacing * SQRT3_2);
        let x = d.x / self.spacing - 0.5 * y;
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        // Not `f64::floor`: a libm call on baseline x86-64, once per mapped point.
        let (fi, fj) = (floor(x), floor(y));
        if !(fi >= 0.0 && fj >= 0.0)
            || fi as usize + 1 >= self.columns
            || fj as usize + 1 >= self.rows
        {
            return None;
        }
        let (i, j) = (fi as usize, fj as usize);
        let (fx, fy) = (x - fi, y - fj);
        let c = 2 * (i + j * (self.columns - 1));
        Some(if fx + fy <= 1.0 {
            (c, [1.0 - fx - fy, fx, fy])
        } else {
            (c + 1, [1.0 - fy, fx + fy - 1.0, 1.0 - fx])
        })
    }

    /// Per lattice triangle, the surface metric (first fundamental form over the plane)
    /// averaged over its area: data triangles count by their plane area at their centroid,
    /// the rest of the triangle as the identity.
    fn average_metrics(
        &self,
        positions: &[DVec3],
        plane: &[DVec2],
        tris: &[[u32; 3]],
    ) -> Vec<[f64; 3]> {
        // Fixed chunks summed in order: the same bits whatever the threads do.
        let partial = |chunk: &[[u32; 3]]| {
            let mut sum = vec![[0.0; 4]; self.cell_count()];
            for t in chunk {
                let [a, b, c] = t.map(|v| v as usize);
                let (u1, u2) = (plane[b] - plane[a], plane[c] - plane[a]);
                let det = u1.perp_dot(u2);
                if det.is_nan() || det <= 0.0 {
                    continue;
                }
                let (x1, x2) = (positions[b] - positions[a], positions[c] - positions[a]);
                // Jacobian columns d/du, d/dv of the linear map sending u1 -> x1, u2 -> x2.
                let ju = (x1 * u2.y - x2 * u1.y) / det;
                let jv = (x2 * u1.x - x1 * u2.x) / det;
                let centroid = (plane[a] + plane[b] + plane[c]) / 3.0;
                if let Some((c, _)) = self.locate(centroid) {
                    let w = 0.5 * det;
                    let s = &mut sum[c];
                    s[0] += w * ju.dot(ju);
                    s[1] += w * ju.dot(jv);
                    s[2] += w * jv.dot(jv);
                    s[3] += w;
                }
            }
            sum
        };
        let partials: Vec<Vec<[f64; 4]>> = tris.par_chunks(METRIC_CHUNK).map(partial).collect();
        let mut sum = vec![[0.0; 4]; self.cell_count()];
        for p in partials {
            for (s, q) in sum.iter_mut().zip(p) {
                for k in 0..4 {
                    s[k] += q[k];
                }
            }
        }
        let cell_area = 3f64.sqrt() / 4.0 * self.spacing * self.spacing;
        sum.into_iter()
            .map(|[guu, guv, gvv, w]| {
                let rest = (cell_area - w).max(0.0);
                let total = (w + rest).max(1e-300);
                capped([(guu + rest) / total, guv / total, (gvv + rest) / total])
            })
            .collect()
    }

    /// Blends toward the identity until the map is one-to-one (at worst the identity).
    fn made_injective(self, rest: &[DVec2]) -> Option<Self> {
        let mut alpha = 1.0;
        for _ in 0..6 {
            let image: Vec<DVec2> = rest
                .iter()
                .zip(&self.image)
                .map(|(r, w)| *r + (*w - *r) * alpha)
                .collect();
            let candidate = Self {
                image,
                blend: alpha,
                ..self.clone()
            };
            if candidate.is_injective() {
                return Some(candidate);
            }
            alpha *= 0.5;
        }
        None
    }

    fn is_injective(&self) -> bool {
        let oriented = (0..self.cell_count()).all(|c| {
            let [a, b, d] = self.triangle(c);
            (self.image[b] - self.image[a]).perp_dot(self.image[d] - self.image[a]) > 0.0
        });
        oriented && simple_polygon(&self.boundary())
    }

    fn boundary(&self) -> Vec<DVec2> {
        let (c, r) = (self.columns, self.rows);
        let at = |i: usize, j: usize| self.image[i + j * c];
        let mut ring = Vec::with_capacity(2 * (c + r));
        ring.extend((0..c).map(|i| at(i, 0)));
        ring.extend((1..r).map(|j| at(c - 1, j)));
        ring.extend((0..c - 1).rev().map(|i| at(i, r - 1)));
        ring.extend((1..r - 1).rev().map(|j| at(0, j)));
        ring
    }
}

/// Local/global ARAP on the lattice: each triangle's rest shape is its plane shape under
/// the square root of its metric (an embedding with the surface's edge lengths).
fn relax(
    lattice: &PlaneWarp,
    rest: &[DVec2],
    metrics: &[[f64; 3]],
    iterations: usize,
) -> Option<Vec<DVec2>> {
    let n = rest.len();
    let cells = lattice.cell_count();
    let mut shapes: Vec<[DVec2; 3]> = Vec::with_capacity(cells);
    let mut weights: Vec<[f64; 3]> = Vec::with_capacity(cells);
    for (c, g) in metrics.iter().enumerate() {
        let root = spd_sqrt(*g);
        let shape = lattice.triangle(c).map(|v| root * rest[v]);
        let mut w = [0.0; 3];
        for k in 0..3 {
            let u = shape[(k + 1) % 3] - shape[k];
            let v = shape[(k + 2) % 3] - shape[k];
            // cot of the angle at k weights the opposite edge; clamped positive so the
            // system stays definite for the obtuse rest shapes strong stretch makes.
            w[k] = 0.5 * (u.dot(v) / u.perp_dot(v).abs().max(1e-300)).clamp(0.05, 20.0);
        }
        shapes.push(shape);
        weights.push(w);
    }
    // A weak pull toward the identity fixes the free translation.
    let pin = 1e-6;
    // Lattice neighbours differ by 1, columns - 1 or columns in index (rows - 1 or rows
    // when numbered column by column): a band matrix along the shorter side.
    let (columns, rows) = (lattice.columns, lattice.rows);
    let by_columns = rows < columns;
    let order = |v: usize| match by_columns {
        true => (v / columns) + (v % columns) * rows,
        false => v,
    };
    let mut system = BandMatrix::new(n, if by_columns { rows } else { columns });
    for (c, w) in weights.iter().enumerate() {
        let t = lattice.triangle(c);
        for (k, &w) in w.iter().enumerate() {
            system.add_edge(order(t[(k + 1) % 3]), order(t[(k + 2) % 3]), w);
        }
    }
    for k in 0..n {
        system.add_edge(k, k, pin);
    }
    let factor = system.cholesky()?;
    let mut image = rest.to_vec();
    let (mut bx, mut by) = (vec![0.0; n], vec![0.0; n]);
    for _ in 0..iterations {
        for (k, r) in rest.iter().enumerate() {
            bx[order(k)] = pin * r.x;
            by[order(k)] = pin * r.y;
        }
        // Each cell's best rotation (the local step), in parallel; the sums into the
        // right-hand side stay serial.
        let rotations: Vec<DMat2> = shapes
            .par_iter()
            .zip(&weights)
            .enumerate()
            .with_min_len(512)
            .map(|(c, (shape, w))| {
                let t = lattice.triangle(c);
                let mut cov = DMat2::ZERO;
                for (k, &wk) in w.iter().enumerate() {
                    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                    let du = image[t[i]] - image[t[j]];
                    let dx = shape[i] - shape[j];
                    cov += DMat2::from_cols(du * dx.x, du * dx.y) * wk;
                }
                // The rotation nearest the covariance: its angle's cosine and sine are
                // the normalised trace and skew part (no atan2 and sin/cos round trip).
                let (cos, sin) = (cov.x_axis.x + cov.y_axis.y, cov.x_axis.y - cov.y_axis.x);
                let r = cos.hypot(sin);
                if r > 0.0 && r.is_finite() {
                    DMat2::from_cols(DVec2::new(cos, sin) / r, DVec2::new(-sin, cos) / r)
                } else {
                    DMat2::IDENTITY
                }
            })
            .collect();
        for (c, ((shape, w), rotation)) in shapes.iter().zip(&weights).zip(&rotations).enumerate() {
            let t = lattice.triangle(c);
            for (k, &wk) in w.iter().enumerate() {
                let (i, j) = (order(t[(k + 1) % 3]), order(t[(k + 2) % 3]));
                let d = rotation * (shape[(k + 1) % 3] - shape[(k + 2) % 3]) * wk;
                bx[i] += d.x;
                by[i] += d.y;
                bx[j] -= d.x;
                by[j] -= d.y;
            }
        }
        // Two independent triangular sweeps over the same factor.
        rayon::join(|| factor.solve(&mut bx), || factor.solve(&mut by));
        for (k, p) in image.iter_mut().enumerate() {
            *p = DVec2::new(bx[order(k)], by[order(k)]);
        }
    }
    if !image.iter().all(|p| p.is_finite()) {
        return None;
    }
    Some(aligned(&image, rest))
}

/// `image` moved rigidly onto `rest` in the least-squares sense, so that the warp does not
/// turn or shift the domain (warm starts keep control grid positions).
fn aligned(image: &[DVec2], rest: &[DVec2]) -> Vec<DVec2> {
    let n = image.len().max(1) as f64;
    let ci = image.iter().copied().sum::<DVec2>() / n;
    let cr = rest.iter().copied().sum::<DVec2>() / n;
    let (mut dot, mut cross) = (0.0, 0.0);
    for (a, b) in image.iter().zip(rest) {
        dot += (*a - ci).dot(*b - cr);
        cross += (*a - ci).perp_dot(*b - cr);
    }
    let turn = DMat2::from_angle(cross.atan2(dot));
    image.iter().map(|p| cr + turn * (*p - ci)).collect()
}

/// Square root of the symmetric positive semi-definite [[a, b], [b, c]].
fn spd_sqrt([a, b, c]: [f64; 3]) -> DMat2 {
    let det = (a * c - b * b).max(0.0).sqrt();
    let t = (a + c + 2.0 * det).max(1e-300).sqrt();
    DMat2::from_cols(DVec2::new(a + det, b), DVec2::new(b, c + det)) * (1.0 / t)
}

/// The metric with its eigenvalues capped at `MAX_DIRECTIONAL_STRETCH^2`.
fn capped([a, b, c]: [f64; 3]) -> [f64; 3] {
    let cap = MAX_DIRECTIONAL_STRETCH * MAX_DIRECTIONAL_STRETCH;
    let mean = 0.5 * (a + c);
    let radius = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (major, minor) = (mean + radius, mean - radius);
    if major <= cap {
        return [a, b, c];
    }
    let v = if b.abs() > 1e-300 {
        DVec2::new(b, major - a).normalize()
    } else if a >= c {
        DVec2::X
    } else {
        DVec2::Y
    };
    let w = v.perp();
    let (m1, m2) = (major.min(cap), minor.min(cap));
    [
        m1 * v.x * v.x + m2 * w.x * w.x,
        m1 * v.x * v.y + m2 * w.x * w.y,
        m1 * v.y * v.y + m2 * w.y * w.y,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A height field z = h(x, y) over the unit square, sampled n x n, as (positions,
    /// projection, triangles).
    fn height_field(
        n: usize,
        h: impl Fn(f64, f64) -> f64,
    ) -> (Vec<DVec3>, Vec<DVec2>, Vec<[u32; 3]>) {
        let mut positions = Vec::new();
        let mut plane = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
                positions.push(DVec3::new(x, y, h(x, y)));
                plane.push(DVec2::new(x, y));
            }
        }
        let mut tris = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = |i: usize, j: usize| (i + j * n) as u32;
                tris.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                tris.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        (positions, plane, tris)
    }

    #[test]
    fn a_flat_patch_is_left_as_it_is() {
        let (positions, plane, tris) = height_field(40, |_, _| 0.25);
        let warp = PlaneWarp::build(&positions, &plane, &tris, 500, 5).expect("warp");
        assert_eq!(warp.blend, 1.0);
        let moved = plane
            .iter()
            .map(|p| (warp.apply(*p) - *p).length())
            .fold(0.0, f64::max);
        assert!(moved < 1e-9, "moved {moved}");
    }

    #[test]
    fn a_steep_part_gets_more_of_the_plane_one_to_one_and_capped() {
        // Flat for x < 0.5, then rising at slope 3 (stretch sqrt(10) = 3.2 along x).
        let (positions, plane, tris) = height_field(60, |x, _| 3.0 * (x - 0.5).max(0.0));
        let warp = PlaneWarp::build(&positions, &plane, &tris, 800, 5).expect("warp");
        assert!(warp.covers(&plane));
        assert!(!warp.covers(&[DVec2::new(5.0, 5.0)]));
        let image: Vec<DVec2> = plane.iter().map(|p| warp.apply(*p)).collect();
        let width = |x0: f64, x1: f64| {
            let at = |x: f64| warp.apply(DVec2::new(x, 0.5)).x;
            at(x1) - at(x0)
        };
        // Away from the crease the steep strip is stretched toward the cap, the flat one
        // is not (the total grows: nothing holds the outer boundary).
        let (flat, steep) = (width(0.1, 0.35), width(0.65, 0.9));
        assert!(steep > 1.6 * flat, "flat {flat}, steep {steep}");
        assert!(
            steep < 2.05 * flat,
            "beyond the cap: flat {flat}, steep {steep}"
        );
        // Across y (no slope) nothing is stretched.
        let height = warp.apply(DVec2::new(0.2, 0.9)).y - warp.apply(DVec2::new(0.2, 0.1)).y;
        assert!((height - 0.8).abs() < 0.08, "height {height}");
        // No data triangle turns over.
        let folded = tris
            .iter()
            .filter(|t| {
                let [a, b, c] = t.map(|v| image[v as usize]);
                (b - a).perp_dot(c - a) <= 0.0
            })
            .count();
        assert_eq!(folded, 0);
    }

    #[test]
    fn a_malformed_warp_covers_nothing() {
        let (positions, plane, tris) = height_field(20, |x, _| x * x);
        let warp = PlaneWarp::build(&positions, &plane, &tris, 200, 3).expect("warp");
        assert!(warp.covers(&plane));
        let mut short = warp.clone();
        short.image.pop();
        assert!(!short.covers(&plane));
        let mut flat = warp.clone();
        flat.rows = 1;
        assert!(!flat.covers(&plane));
        let mut broken = warp;
        broken.image[0].x = f64::NAN;
        assert!(!broken.covers(&plane));
    }

    #[test]
    fn simple_polygons_are_told_from_self_crossing_ones() {
        let square = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        assert!(simple_polygon(&square));
        let bow_tie = [square[0], square[1], square[3], square[2]];
        assert!(!simple_polygon(&bow_tie));
        // A lattice rim: straight sides of many collinear edges, which must not count as
        // meeting each other.
        let mut rim: Vec<DVec2> = (0..20).map(|i| DVec2::new(i as f64, 0.0)).collect();
        rim.extend((0..20).map(|j| DVec2::new(20.0, j as f64)));
        rim.extend((0..20).map(|i| DVec2::new(20.0 - i as f64, 20.0)));
        rim.extend((0..20).map(|j| DVec2::new(0.0, 20.0 - j as f64)));
        assert!(simple_polygon(&rim));
        // The same rim with one vertex pushed across the opposite side.
        let mut crossed = rim.clone();
        crossed[10] = DVec2::new(10.0, 25.0);
        assert!(!simple_polygon(&crossed));
        // Touching without crossing (a vertex on a non-adjacent edge) is not simple either.
        let mut touching = rim;
        touching[30] = DVec2::new(10.0, 0.0);
        assert!(!simple_polygon(&touching));
    }

    #[test]
    fn the_metric_cap_keeps_directions_and_limits_lengths() {
        // Stretch 4 along (1, 1) / sqrt(2), none across.
        let v = DVec2::new(1.0, 1.0).normalize();
        let g = |l: f64| {
            [
                1.0 + (l - 1.0) * v.x * v.x,
                (l - 1.0) * v.x * v.y,
                1.0 + (l - 1.0) * v.y * v.y,
            ]
        };
        let [a, b, c] = capped(g(16.0));
        let along = a * v.x * v.x + 2.0 * b * v.x * v.y + c * v.y * v.y;
        let w = v.perp();
        let across = a * w.x * w.x + 2.0 * b * w.x * w.y + c * w.y * w.y;
        let cap = MAX_DIRECTIONAL_STRETCH * MAX_DIRECTIONAL_STRETCH;
        assert!((along - cap).abs() < 1e-12 && (across - 1.0).abs() < 1e-12);
        assert_eq!(capped(g(2.0)), g(2.0));
    }
}
