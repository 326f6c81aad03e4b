//! Which part of a scan's tessellation is shown: where the surface was fitted, never where
//! it only extrapolates, and nowhere farther from the data than the hole-bridging distance.

use super::object::STRAY_LIMIT_SHARE;
use super::scan::ScanFit;
use super::PatchFit;
use crate::remesh::param::Locator;
use crate::surface::bezier::{lattice_points, lattice_triangles};
use crate::surface::{Derivatives, SurfaceParam};
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use rstar::RTree;

/// The scanned region in parameter space, and what of the tessellation is shown of it.
///
/// Two sources, united per tessellation vertex:
/// - the triangles of the mapped patch (data and bridged hole fills) with the data vertices
///   at their corrected parameters. A triangle that the correction stretched to more than
///   `MAX_STRETCH` times its mapped size (a foot point that slid far, typically on a
///   grazing wall) or that touches a fold of the map is left out of this source: there the
///   mapped triangles say little about where the data lie.
/// - the fitted data's footprint: every data point that the surface passes within `reach`
///   of marks the corners of the tessellation triangle its parameter lies in, when all of
///   them lie within `reach` of the point. Triangles of the mapped patch are too coarse a
///   guide at the rims (a tessellation triangle only partly inside the last data triangle
///   would be lost, and with it the rim's points) and say nothing where they were left out
///   above; the data's own parameters are exact there.
///
/// A tessellation triangle is shown when its three corners are. A triangle holding a
/// footprint point but not shown whole (at the rims, where the map squeezes a grazing wall
/// into a sliver of parameters, one tessellation triangle spans millimetres and sticks out
/// past the data) is cut finer, and the pieces whose corners all lie within `reach` of a
/// footprint point are shown: the shown surface reaches the rim's points without standing
/// farther from the data than `reach` anywhere the footprint decides.
pub struct Coverage {
    triangles: Vec<[u32; 3]>,
    params: Vec<DVec2>,
    /// Parameters of the data points the surface passes within `reach` of...
    footprint: Vec<DVec2>,
    /// ... and those points.
    footprint_points: Vec<DVec3>,
    /// How far a shown vertex marked by a data point may stand from it.
    reach: f64,
}

const MAX_STRETCH: f64 = 3.0;

/// At most this many segments per side when a rim triangle is cut finer (a 10 mm sliver
/// at a 1.2 mm reach needs 17; longer ones are rarer than one in a thousand triangles).
const MAX_CUT: usize = 24;

impl Coverage {
    /// `corrected[v]`: the final parameter of data vertex v (fewer than `mapped`, whose
    /// remaining entries are hole-fill vertices); `mapped[v]`: the parameter of the plain map;
    /// `untrusted[v]`: a vertex of a folded triangle of the map, whose triangles are left out
    /// (at a folded silhouette the map overlaps itself and the mapped triangles are a guess).
    /// No footprint: see [`Coverage::with_footprint`].
    pub fn new(
        triangles: &[[u32; 3]],
        corrected: &[SurfaceParam],
        mapped: &[DVec2],
        untrusted: &[bool],
    ) -> Self {
        let params: Vec<DVec2> = mapped
            .iter()
            .enumerate()
            .map(|(v, m)| corrected.get(v).map_or(*m, |q| DVec2::new(q.u, q.v)))
            .collect();
        let triangles = triangles
            .par_iter()
            .copied()
            .filter(|t| !t.iter().any(|&v| untrusted.get(v as usize) == Some(&true)))
            .filter(|t| {
                (0..3).all(|k| {
                    let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                    (params[a] - params[b]).length()
                        <= MAX_STRETCH * (mapped[a] - mapped[b]).length() + 1e-12
                })
            })
            .collect();
        Self {
            triangles,
            params,
            footprint: Vec::new(),
            footprint_points: Vec::new(),
            reach: 0.0,
        }
    }

    /// Adds the fitted data's footprint: the data points whose geometric error is at most
    /// `reach` (a point the surface misses by more does not vouch for the surface at its
    /// parameter), at their parameters. A tessellation triangle holding one is shown whole
    /// when all its corners lie within `reach` of the point, else in the pieces that lie
    /// within `reach` of the footprint (where the map squeezes the surface, one triangle of
    /// parameters can span far more than that).
    pub fn with_footprint(
        mut self,
        params: &[SurfaceParam],
        points: &[DVec3],
        errors: &[f64],
        reach: f64,
    ) -> Self {
        let near: Vec<usize> = (0..params.len().min(points.len()).min(errors.len()))
            .filter(|&k| errors[k] <= reach)
            .collect();
        self.footprint = near
            .iter()
            .map(|&k| DVec2::new(params[k].u, params[k].v))
            .collect();
        self.footprint_points = near.iter().map(|&k| points[k]).collect();
        self.reach = reach;
        self
    }

    /// The scanned region of a scan fit: its mapped patch and the footprint of the data
    /// the surface passes within the hole-bridging distance of (the furthest the shown
    /// surface may stand from a measured point), but never farther than the stray bound
    /// every surface is held to (`STRAY_LIMIT_SHARE` of the data's bounding-box
    /// diagonal): on a small or coarse patch the bridging distance, a few point spacings,
    /// is several percent of its size, and the shown surface ran on past the rim by that.
    pub fn of(fit: &PatchFit, scan: &ScanFit) -> Self {
        let reach = scan
            .trims
            .plan
            .max_bridge
            .min(STRAY_LIMIT_SHARE * crate::numeric::bounds_diagonal(&fit.data));
        Self::new(
            &scan.trims.plan.covered,
            &fit.params,
            &scan.mapping.mapped_params,
            &scan.mapping.near_fold,
        )
        .with_footprint(&fit.params, &fit.data, &fit.geometric_errors, reach)
    }

    /// Returns a test for parameters: inside a kept triangle of the mapped patch.
    pub(crate) fn tester(&self) -> impl Fn(f64, f64) -> bool + Sync + '_ {
        let locator = Locator::new(&self.triangles, &self.params);
        move |u, v| !self.triangles.is_empty() && locator.contains(DVec2::new(u, v))
    }

    /// The triangles of a tessellation (vertices at `params`, surface there `evals`) that
    /// are shown; `mapped` tells a parameter inside the mapped region. The pieces of rim
    /// triangles are appended to `params` and `evals` (evaluated by `evaluate`), their
    /// triangles to the result.
    pub(crate) fn shown(
        &self,
        mapped: impl Fn(f64, f64) -> bool + Sync,
        params: &mut Vec<SurfaceParam>,
        evals: &mut Vec<Derivatives>,
        triangles: Vec<[u32; 3]>,
        evaluate: &(dyn Fn(SurfaceParam) -> Derivatives + Sync),
    ) -> Vec<[u32; 3]> {
        let mut inside: Vec<bool> = params.par_iter().map(|p| mapped(p.u, p.v)).collect();
        let mut rims = Vec::new();
        if !self.footprint.is_empty() && !triangles.is_empty() {
            let plane: Vec<DVec2> = params.iter().map(|p| DVec2::new(p.u, p.v)).collect();
            let locator = Locator::new(&triangles, &plane);
            let holding: Vec<(usize, bool)> = self
                .footprint
                .par_iter()
                .zip(self.footprint_points.par_iter())
                .filter_map(|(&q, &p)| {
                    let (t, _) = locator.locate(q);
                    let corners = triangles[t].map(|v| plane[v as usize]);
                    let near = triangles[t]
                        .iter()
                        .all(|&v| evals[v as usize].position.distance(p) <= self.reach);
                    holds(corners, q).then_some((t, near))
                })
                .collect();
            for (t, near) in holding {
                if near {
                    for v in triangles[t] {
                        inside[v as usize] = true;
                    }
                } else {
                    rims.push(t);
                }
            }
        }
        let whole = |t: &[u32; 3]| t.iter().all(|&v| inside[v as usize]);
        rims.sort_unstable();
        rims.dedup();
        rims.retain(|&t| !whole(&triangles[t]));
        let mut shown: Vec<[u32; 3]> = triangles.iter().copied().filter(whole).collect();
        if rims.is_empty() {
            return shown;
        }
        let tree = RTree::bulk_load(self.footprint_points.iter().map(|p| p.to_array()).collect());
        let pieces: Vec<Pieces> = rims
            .par_iter()
            .map(|&t| {
                let corners =
                    triangles[t].map(|v| (params[v as usize], evals[v as usize].position));
                self.near_pieces(corners, &tree, evaluate)
            })
            .collect();
        for piece in pieces {
            let base = params.len() as u32;
            params.extend(piece.params);
            evals.extend(piece.evals);
            shown.extend(piece.triangles.iter().map(|t| t.map(|v| v + base)));
        }
        shown
    }

    /// The rim triangle with these corners (parameter, surface point) cut into a lattice
    /// fine enough that a piece spans at most half of `reach`, and the pieces whose corners
    /// all lie within `reach` of a footprint point. The lattice is the triangle's own
    /// affine image, so the pieces keep its orientation.
    fn near_pieces(
        &self,
        corners: [(SurfaceParam, DVec3); 3],
        tree: &RTree<[f64; 3]>,
        evaluate: &(dyn Fn(SurfaceParam) -> Derivatives + Sync),
    ) -> Pieces {
        let size = (0..3)
            .map(|k| corners[k].1.distance(corners[(k + 1) % 3].1))
            .fold(0.0f64, f64::max);
        let n = ((2.0 * size / self.reach).ceil() as usize).clamp(2, MAX_CUT);
        let [(a, _), (b, _), (c, _)] = corners;
        let params: Vec<SurfaceParam> = lattice_points(n)
            .into_iter()
            .map(|(i, j)| {
                let (s, t) = (i as f64 / n as f64, j as f64 / n as f64);
                SurfaceParam {
                    face: a.face,
                    u: a.u + s * (b.u - a.u) + t * (c.u - a.u),
                    v: a.v + s * (b.v - a.v) + t * (c.v - a.v),
                }
            })
            .collect();
        let evals: Vec<Derivatives> = params.iter().map(|p| evaluate(*p)).collect();
        let reach2 = self.reach * self.reach;
        let near: Vec<bool> = evals
            .iter()
            .map(|e| {
                tree.nearest_neighbor(&e.position.to_array())
                    .is_some_and(|q| DVec3::from_array(*q).distance_squared(e.position) <= reach2)
            })
            .collect();
        let mut triangles: Vec<[u32; 3]> = lattice_triangles(n)
            .into_iter()
            .filter(|t| t.iter().all(|&v| near[v as usize]))
            .collect();
        // Only the lattice vertices a shown piece uses go into the GLB.
        let mut index = vec![u32::MAX; params.len()];
        let mut kept = Pieces {
            params: Vec::new(),
            evals: Vec::new(),
            triangles: Vec::new(),
        };
        for t in &mut triangles {
            for v in t.iter_mut() {
                let slot = &mut index[*v as usize];
                if *slot == u32::MAX {
                    *slot = kept.params.len() as u32;
                    kept.params.push(params[*v as usize]);
                    kept.evals.push(evals[*v as usize]);
                }
                *v = *slot;
            }
        }
        kept.triangles = triangles;
        kept
    }
}

/// A rim triangle cut finer: its lattice's parameters and surface, and the pieces shown.
struct Pieces {
    params: Vec<SurfaceParam>,
    evals: Vec<Derivatives>,
    triangles: Vec<[u32; 3]>,
}

/// Whether `q` lies in the triangle `c` or within a quarter of its size outside it (a data
/// parameter on the surface's last edge, beside rounding).
fn holds(c: [DVec2; 3], q: DVec2) -> bool {
    let det = (c[1] - c[0]).perp_dot(c[2] - c[0]);
    if det == 0.0 {
        return false;
    }
    let l1 = (q - c[0]).perp_dot(c[2] - c[0]) / det;
    let l2 = (c[1] - c[0]).perp_dot(q - c[0]) / det;
    (1.0 - l1 - l2).min(l1).min(l2) >= -0.25
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plane z = 0 with (u, v) as its coordinates.
    fn flat(p: SurfaceParam) -> Derivatives {
        Derivatives {
            position: DVec3::new(p.u, p.v, 0.0),
            du: DVec3::X,
            dv: DVec3::Y,
            ..Derivatives::default()
        }
    }

    fn at(u: f64, v: f64) -> SurfaceParam {
        SurfaceParam { face: 0, u, v }
    }

    /// One fitted point at (1, 1), within reach 1.5 of the surface: the footprint alone
    /// decides (nothing is inside a mapped patch).
    fn one_point(reach: f64) -> Coverage {
        Coverage::new(&[], &[], &[], &[]).with_footprint(
            &[at(1.0, 1.0)],
            &[DVec3::new(1.0, 1.0, 0.2)],
            &[0.2],
            reach,
        )
    }

    #[test]
    fn a_triangle_near_its_point_is_shown_whole() {
        let mut params = vec![at(0.0, 0.0), at(2.0, 0.0), at(0.0, 2.0)];
        let mut evals: Vec<Derivatives> = params.iter().map(|p| flat(*p)).collect();
        let shown = one_point(2.5).shown(
            |_, _| false,
            &mut params,
            &mut evals,
            vec![[0, 1, 2]],
            &flat,
        );
        assert_eq!(shown, vec![[0, 1, 2]]);
        assert_eq!(params.len(), 3, "nothing cut");
    }

    #[test]
    fn a_rim_triangle_spanning_past_the_reach_shows_only_its_pieces_near_the_data() {
        let reach = 1.5;
        let point = DVec3::new(1.0, 1.0, 0.2);
        let mut params = vec![at(0.0, 0.0), at(10.0, 0.0), at(0.0, 10.0), at(10.0, 10.0)];
        let mut evals: Vec<Derivatives> = params.iter().map(|p| flat(*p)).collect();
        // The second triangle holds no point: it stays hidden, cut or not.
        let shown = one_point(reach).shown(
            |_, _| false,
            &mut params,
            &mut evals,
            vec![[0, 1, 2], [1, 3, 2]],
            &flat,
        );
        assert!(!shown.is_empty(), "the point's surroundings are shown");
        assert!(!shown.contains(&[0, 1, 2]), "not the whole 10 m triangle");
        let used: Vec<u32> = shown.iter().flatten().copied().collect();
        for &v in &used {
            let p = evals[v as usize].position;
            assert!(
                p.distance(point) <= reach + 1e-12,
                "{p} is beyond the reach"
            );
            assert!(
                p.x + p.y <= 10.0 + 1e-12,
                "{p} is outside the holding triangle"
            );
        }
        // The point's own foot (1, 1) lies in a shown piece: it is covered.
        let q = DVec2::new(1.0, 1.0);
        let covered = shown.iter().any(|t| {
            let c = t.map(|v| evals[v as usize].position.truncate());
            let det = (c[1] - c[0]).perp_dot(c[2] - c[0]);
            let l1 = (q - c[0]).perp_dot(c[2] - c[0]) / det;
            let l2 = (c[1] - c[0]).perp_dot(q - c[0]) / det;
            (1.0 - l1 - l2).min(l1).min(l2) >= -1e-12
        });
        assert!(covered, "the point's parameter is in a shown piece");
        // Pieces keep the orientation of the triangle they were cut from.
        for t in &shown {
            let [a, b, c] = t.map(|v| evals[v as usize].position);
            assert!((b - a).cross(c - a).z > 0.0);
        }
    }
}
