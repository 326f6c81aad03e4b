//! Geometric error: the distance from a data point to its foot point on the surface,
//! found by Newton iterations on `|S(u) - p|^2` started from the data point's parameter.

use crate::numeric::packed_outer;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use rayon::prelude::*;

/// Newton iterations per point. Started from the fitting parameter the foot point is
/// usually within a small fraction of a face; a handful of steps reaches machine precision.
const MAX_NEWTON_STEPS: usize = 8;

/// Squared parameter step (in face units) below which the search has converged.
const CONVERGED_STEP2: f64 = 1e-12;

/// Squared parameter step (in face units) below which the last step is taken on the
/// second-order Taylor expansion instead of a fresh evaluation. Newton converges
/// quadratically here (measured on bun000's rounds: steps of ~1e-2, then ~1e-4, then
/// ~1e-7 of a face), so after a step under 1e-3 the foot is within ~1e-6 of a face of the
/// expansion's point: as close as the convergence test above asks, one evaluation
/// earlier. The surface moves each round by a few percent of a face along itself, so
/// without this most points paid a third evaluation only to confirm the second step.
const TAYLOR_STEP2: f64 = 1e-6;

/// Returns the foot-point parameter and the surface's derivatives there (the distance is
/// `|position - point|`). The distance never exceeds the distance at `start`: a step that
/// does not reduce it is halved and finally refused.
/// `evaluate` is the surface's evaluator for the control set (`TriSurface::evaluator`).
pub(crate) fn foot_point<S: TriSurface + ?Sized>(
    surface: &S,
    evaluate: &(impl Fn(SurfaceParam) -> Derivatives + ?Sized),
    point: DVec3,
    start: SurfaceParam,
) -> (SurfaceParam, Derivatives) {
    let mut param = start;
    let mut d = evaluate(param);
    let mut dist2 = (d.position - point).length_squared();
    for _ in 0..MAX_NEWTON_STEPS {
        let r = d.position - point;
        let g = [d.du.dot(r), d.dv.dot(r)];
        // Full Hessian where it is positive definite, Gauss-Newton otherwise.
        let full = [
            d.du.dot(d.du) + d.duu.dot(r),
            d.du.dot(d.dv) + d.duv.dot(r),
            d.dv.dot(d.dv) + d.dvv.dot(r),
        ];
        let gauss = [d.du.dot(d.du), d.du.dot(d.dv), d.dv.dot(d.dv)];
        let det_full = full[0] * full[2] - full[1] * full[1];
        let h = if full[0] > 0.0 && det_full > 1e-300 {
            full
        } else {
            gauss
        };
        let det = h[0] * h[2] - h[1] * h[1];
        if det.abs() < 1e-300 {
            break;
        }
        let mut du = -(h[2] * g[0] - h[1] * g[1]) / det;
        let mut dv = -(h[0] * g[1] - h[1] * g[0]) / det;
        // Newton converges quadratically: a step this short moves the point by under
        // 1e-6 of a face (~1 nm on a 40k-point scan), and the distance, stationary at the
        // foot, by far less; not worth another evaluation (1e-7 of a face: 3.4 evaluations
        // per point, 1e-6: 3.2 for the same fits; 1e-5 (3.0) already moved one Stanford
        // fit's rounds elsewhere).
        let step2 = du * du + dv * dv;
        if step2 < CONVERGED_STEP2 {
            break;
        }
        if step2 < TAYLOR_STEP2
            && taylor_step(surface, &mut param, &mut d, &mut dist2, point, du, dv)
        {
            break;
        }
        let mut improved = false;
        for _ in 0..6 {
            let trial = surface.step(param, du, dv);
            let td = evaluate(trial);
            let t2 = (td.position - point).length_squared();
            if t2 < dist2 {
                param = trial;
                d = td;
                dist2 = t2;
                improved = true;
                break;
            }
            du *= 0.5;
            dv *= 0.5;
        }
        if !improved {
            break;
        }
    }
    (param, d)
}

/// The last, short Newton step on the expansion at `param`: position to second order,
/// first derivatives to first order (the second derivatives stay). Refused (false) where
/// the step leaves the face's coordinates (clipped by the domain, or onto another face of
/// a mesh surface) or the expansion does not come nearer `point`: the caller then takes
/// the step with an evaluation, as any other.
fn taylor_step<S: TriSurface + ?Sized>(
    surface: &S,
    param: &mut SurfaceParam,
    d: &mut Derivatives,
    dist2: &mut f64,
    point: DVec3,
    du: f64,
    dv: f64,
) -> bool {
    let trial = surface.step(*param, du, dv);
    if trial.face != param.face || trial.u != param.u + du || trial.v != param.v + dv {
        return false;
    }
    let first = d.du * du + d.dv * dv;
    let second = d.duu * (du * du) + d.duv * (2.0 * du * dv) + d.dvv * (dv * dv);
    let position = d.position + first + second * 0.5;
    let t2 = (position - point).length_squared();
    if t2 > *dist2 {
        return false;
    }
    *param = trial;
    *dist2 = t2;
    d.position = position;
    d.du += d.duu * du + d.duv * dv;
    d.dv += d.duv * du + d.dvv * dv;
    true
}

/// The curvature's share of the squared distance from a data point to a surface that
/// moves near its foot point (Pottmann & Hofer 2003; the squared-distance minimisation of
/// Wang, Pottmann & Liu 2006, fitted to subdivision surfaces by Cheng, Wang et al. 2004):
/// to second order, moving the surface by x along principal direction e_i changes the
/// squared distance by c_i x^2, c_i = |d k_i| / (1 + |d k_i|), where the surface bends
/// away from the point (d, the point's offset along `normal`, and k_i, the principal
/// curvature towards `normal`, of opposite signs). Where it bends towards the point the
/// exact coefficient is negative, and SDM takes 0 there, which keeps the term convex.
/// Returned as C = c_1 e_1 e_1^T + c_2 e_2 e_2^T, entries xx, xy, xz, yy, yz, zz (zero
/// where the tangents degenerate). A constant tangential share instead damps every slide
/// alike, too much where the surface is flat (slow rounds) or too little where it is
/// curved (refused rounds).
pub(crate) fn curvature_term(d: &Derivatives, normal: DVec3, offset: DVec3) -> [f64; 6] {
    let (e, f, g) = (d.du.dot(d.du), d.du.dot(d.dv), d.dv.dot(d.dv));
    let (l, m, n) = (d.duu.dot(normal), d.duv.dot(normal), d.dvv.dot(normal));
    let det = e * g - f * f;
    let along = offset.dot(normal);
    if det <= 0.0 || !det.is_finite() || along == 0.0 {
        return [0.0; 6];
    }
    // Principal curvatures: the eigenvalues of the shape operator I^-1 II.
    let sum = (e * n - 2.0 * f * m + g * l) / det;
    let product = (l * n - m * m) / det;
    let spread = (0.25 * sum * sum - product).max(0.0).sqrt();
    let k = [0.5 * sum + spread, 0.5 * sum - spread];
    let c = k.map(|k| {
        let a = along * k;
        if a < 0.0 {
            -a / (1.0 - a)
        } else {
            0.0
        }
    });
    // The first principal direction: the null vector of II - k_1 I, from its longer row
    // (any direction at an umbilic, where c_1 = c_2).
    let rows = [[l - k[0] * e, m - k[0] * f], [m - k[0] * f, n - k[0] * g]];
    let row = if rows[0][0].hypot(rows[0][1]) >= rows[1][0].hypot(rows[1][1]) {
        rows[0]
    } else {
        rows[1]
    };
    let e1 = (d.du * -row[1] + d.dv * row[0])
        .try_normalize()
        .or_else(|| d.du.try_normalize());
    let Some(e1) = e1 else {
        return [0.0; 6];
    };
    let e2 = normal.cross(e1);
    let (a, b) = (packed_outer(e1, c[0]), packed_outer(e2, c[1]));
    std::array::from_fn(|i| a[i] + b[i])
}

/// Distance of every data point to its foot point, Newton started at its parameter.
pub(crate) fn geometric_errors(
    surface: &dyn TriSurface,
    controls: &[DVec3],
    data: &[DVec3],
    params: &[SurfaceParam],
) -> Vec<f64> {
    let evaluate = surface.evaluator(controls);
    data.par_iter()
        .zip(params.par_iter())
        .map(|(p, u)| (foot_point(surface, &*evaluate, *p, *u).1.position - *p).length())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::grid_spline::GridSpline;
    use glam::DVec2;

    /// A 10 x 10 cell Loop grid whose controls sit on a curved height field (radii of
    /// curvature of a few cells, as on a scan's detailed parts).
    fn bumpy_grid() -> (GridSpline, Vec<DVec3>) {
        let cells = (0..10).flat_map(|i| (0..10).flat_map(move |j| [(i, j, false), (i, j, true)]));
        let grid = GridSpline::new(cells);
        let controls = grid
            .control_coords()
            .iter()
            .map(|&(i, j)| {
                let (x, y) = (i as f64 + 0.5 * j as f64, j as f64 * 0.75f64.sqrt());
                DVec3::new(x, y, 0.8 * (0.6 * x).sin() * (0.45 * y).cos())
            })
            .collect();
        (grid, controls)
    }

    #[test]
    fn foot_points_are_stationary_and_their_derivatives_are_the_surface_s() {
        let (grid, controls) = bumpy_grid();
        let evaluate = grid.evaluator(&controls);
        let evaluations = std::sync::atomic::AtomicUsize::new(0);
        let counted = |p: SurfaceParam| {
            evaluations.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            evaluate(p)
        };
        let mut checked = 0;
        let mut worst: f64 = 0.0;
        for k in 0..400 {
            // Spread over the inner cells; start a few percent of a cell off the foot and
            // the point off the surface by up to a tenth of a cell, as in a fit's rounds.
            let (a, b) = ((k % 20) as f64 * 0.3 + 2.0, (k / 20) as f64 * 0.3 + 2.0);
            let on = evaluate(SurfaceParam {
                face: 0,
                u: a,
                v: b,
            });
            let normal = on.du.cross(on.dv).normalize();
            let offset = 0.1 * ((k as f64 * 0.77).sin());
            let point = on.position + normal * offset;
            let start = SurfaceParam {
                face: 0,
                u: a + 0.04 * (k as f64 * 1.3).cos(),
                v: b + 0.04 * (k as f64 * 2.1).sin(),
            };
            let start_distance = (evaluate(start).position - point).length();
            let (foot, d) = foot_point(&grid, &counted, point, start);
            let fresh = evaluate(foot);
            // What the search returns is the surface at the returned parameter, also when
            // its last step came from the expansion.
            assert!(
                (fresh.position - d.position).length() < 1e-9,
                "{k}: position"
            );
            assert!(
                (fresh.du - d.du).length() < 1e-6 * fresh.du.length(),
                "{k}: du"
            );
            assert!(
                (fresh.dv - d.dv).length() < 1e-6 * fresh.dv.length(),
                "{k}: dv"
            );
            // A foot point: the residual is normal to the surface there...
            // (the Gauss-Newton step still to go, in cells, within the search's tolerance)...
            let r = fresh.position - point;
            let (g, h) = (
                [fresh.du.dot(r), fresh.dv.dot(r)],
                [
                    fresh.du.dot(fresh.du),
                    fresh.du.dot(fresh.dv),
                    fresh.dv.dot(fresh.dv),
                ],
            );
            let det = h[0] * h[2] - h[1] * h[1];
            let to_go = DVec2::new(h[2] * g[0] - h[1] * g[1], h[0] * g[1] - h[1] * g[0]) / det;
            worst = worst.max(to_go.length());
            assert!(
                to_go.length() < 1e-5,
                "{k}: {:e} of a cell still to go",
                to_go.length()
            );
            // ... and not farther than where the search started.
            assert!(r.length() <= start_distance + 1e-15, "{k}");
            assert!(
                r.length() <= offset.abs() + 1e-9,
                "{k}: not the nearest foot"
            );
            checked += 1;
        }
        assert_eq!(checked, 400);
        // Two Newton steps from a few percent of a cell: the second from the expansion.
        let per_point = evaluations.into_inner() as f64 / 400.0;
        eprintln!("worst step to go {worst:e}, {per_point} evaluations per point");
        assert!(per_point < 2.5, "{per_point} evaluations per point");
    }

    /// A cylinder of radius `radius` about the z axis, parameterised at angle `u` and height
    /// `v` (scaled so the parameters are not arc length, and sheared by `shear` so that
    /// they need not be orthogonal either), and its outward normal.
    fn cylinder(radius: f64, u: f64, v: f64, shear: f64) -> (Derivatives, DVec3) {
        let (s, c) = (2.0 * u).sin_cos();
        let d = Derivatives {
            position: DVec3::new(radius * c, radius * s, 3.0 * v + shear * u),
            du: DVec3::new(-2.0 * radius * s, 2.0 * radius * c, shear),
            dv: DVec3::new(0.0, 0.0, 3.0),
            duu: DVec3::new(-4.0 * radius * c, -4.0 * radius * s, 0.0),
            duv: DVec3::ZERO,
            dvv: DVec3::ZERO,
        };
        (d, DVec3::new(c, s, 0.0))
    }

    fn quadratic_form(c: &[f64; 6], x: DVec3) -> f64 {
        x.dot(crate::numeric::packed_mul(c, x))
    }

    /// The term is the second-order change of the exact squared distance: a point outside
    /// a cylinder, the cylinder moved by x across its axis, is sqrt((R + d)^2 + x^2) - R
    /// from it, d^2 + d x^2 / (R + d) to second order; moved along its axis, d from it.
    /// Inside, moving the cylinder across brings it nearer (the exact term is negative) and
    /// SDM takes none.
    #[test]
    fn the_curvature_term_is_the_second_order_change_of_the_squared_distance() {
        let radius = 2.0;
        for shear in [0.0, 1.7] {
            let (d, normal) = cylinder(radius, 0.3, -0.4, shear);
            second_order_on_a_cylinder(&d, normal, radius);
        }
    }

    fn second_order_on_a_cylinder(d: &Derivatives, normal: DVec3, radius: f64) {
        let across = normal.cross(DVec3::Z);
        for offset in [0.05, 0.4] {
            let c = curvature_term(d, normal, normal * offset);
            let squared = |x: f64| (((radius + offset).powi(2) + x * x).sqrt() - radius).powi(2);
            let h = 1e-3;
            let exact = (squared(h) - 2.0 * squared(0.0) + squared(-h)) / (2.0 * h * h);
            let term = quadratic_form(&c, across);
            assert!(
                (term - exact).abs() < 1e-6,
                "{offset}: {term} against {exact}"
            );
            assert!((term - offset / (radius + offset)).abs() < 1e-12);
            assert!(quadratic_form(&c, DVec3::Z).abs() < 1e-12);
            assert!(quadratic_form(&c, normal).abs() < 1e-12);
        }
        let inside = curvature_term(d, normal, normal * -0.3);
        assert!(inside.iter().all(|x| x.abs() < 1e-12), "{inside:?}");
        // On a plane no direction costs anything.
        let flat = Derivatives {
            duu: DVec3::ZERO,
            ..*d
        };
        assert_eq!(curvature_term(&flat, normal, normal * 0.2), [0.0; 6]);
    }
}
