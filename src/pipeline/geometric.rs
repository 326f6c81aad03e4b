//! Geometric error: the distance from a data point to its foot point on the surface,
//! found by Newton iterations on `|S(u) - p|^2` started from the data point's parameter.

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
}
