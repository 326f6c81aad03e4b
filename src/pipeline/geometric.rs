//! Geometric error: the distance from a data point to its foot point on the surface,
//! found by Newton iterations on `|S(u) - p|^2` started from the data point's parameter.

use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;

/// Newton iterations per point. Started from the fitting parameter the foot point is
/// usually within a small fraction of a face; a handful of steps reaches machine precision.
const MAX_NEWTON_STEPS: usize = 8;

/// Squared parameter step (in face units) below which the search has converged.
const CONVERGED_STEP2: f64 = 1e-12;

/// Returns the foot-point parameter and the surface's derivatives there (the distance is
/// `|position - point|`). The distance never exceeds the distance at `start`: a step that
/// does not reduce it is halved and finally refused.
/// `evaluate` is the surface's evaluator for the control set (`TriSurface::evaluator`).
pub fn foot_point(
    surface: &dyn TriSurface,
    evaluate: &(dyn Fn(SurfaceParam) -> Derivatives + Sync),
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
        if du * du + dv * dv < CONVERGED_STEP2 {
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

/// A blue-green-yellow-red ramp over `error / tolerance` in [0, 2]: blue is exact, green
/// half the tolerance, yellow the tolerance, red twice it or more.
pub fn error_colour(error: f64, tolerance: f64) -> [f32; 4] {
    let t = if tolerance > 0.0 {
        (error / tolerance).clamp(0.0, 2.0) / 2.0
    } else {
        0.0
    } as f32;
    let stops: [[f32; 3]; 5] = [
        [0.10, 0.25, 0.90],
        [0.10, 0.75, 0.30],
        [0.95, 0.90, 0.10],
        [0.95, 0.50, 0.10],
        [0.85, 0.10, 0.10],
    ];
    let x = t * 4.0;
    let i = (x.floor() as usize).min(3);
    let f = x - i as f32;
    let a = stops[i];
    let b = stops[i + 1];
    [
        a[0] + (b[0] - a[0]) * f,
        a[1] + (b[1] - a[1]) * f,
        a[2] + (b[2] - a[2]) * f,
        1.0,
    ]
}
