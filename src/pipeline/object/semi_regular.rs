//! The paper's "mesh adjustment" over a simplified base domain: the base control mesh
//! subdivided `levels` times by Loop's 1-to-4 split (Lee et al. 1998's semi-regular
//! remesh, in connectivity), so that every vertex the split adds is regular (valence 6
//! inside, 4 on a boundary) and only the base's own vertices can be extraordinary. Each
//! data point's parameter on a base face maps exactly onto one of its four children: the
//! split is affine in the face's barycentric coordinates.

use crate::mesh::loop_subdiv::loop_step_with_creases;
use crate::mesh::topology::{Topology, TopologyError};
use crate::surface::SurfaceParam;
use crate::TriMesh;

/// A control mesh with the data's parameters on its faces and its crease edges.
pub(super) type ParamMesh = (TriMesh, Vec<SurfaceParam>, Vec<[u32; 2]>);

/// A base control mesh split `levels` times: the fine mesh (its first vertices are the
/// base's, in order; the positions are the Loop-subdivided ones), the data parameters moved
/// onto the fine faces, and the fine crease edges.
pub(super) fn split_domain(
    base: TriMesh,
    params: Vec<SurfaceParam>,
    creases: Vec<[u32; 2]>,
    levels: usize,
) -> Result<ParamMesh, TopologyError> {
    let (mut mesh, mut params, mut creases) = (base, params, creases);
    for _ in 0..levels {
        let topo = Topology::from_mesh(&mesh)?;
        let (step, fine_creases) = loop_step_with_creases(&topo, &creases);
        let positions = step.operator.apply(&mesh.positions);
        mesh = TriMesh::new(positions, step.triangles);
        params = params.into_iter().map(child_param).collect();
        creases = fine_creases;
    }
    Ok((mesh, params, creases))
}

/// The parameter on the child of a 1-to-4 split that holds the point. The children of
/// face `f` with corners (t0, t1, t2) and edge midpoints m0 = t0t1, m1 = t1t2, m2 = t2t0
/// are `4f + k`: [t0, m0, m2], [t1, m1, m0], [t2, m2, m1], [m0, m1, m2]
/// (`loop_step_with_creases`' order).
fn child_param(p: SurfaceParam) -> SurfaceParam {
    let (u, v) = (p.u, p.v);
    let w = 1.0 - u - v;
    let (k, cu, cv) = if u >= 0.5 {
        (0, 2.0 * u - 1.0, 2.0 * v)
    } else if v >= 0.5 {
        (1, 2.0 * v - 1.0, 2.0 * w)
    } else if w >= 0.5 {
        (2, 2.0 * w - 1.0, 2.0 * u)
    } else {
        (3, 1.0 - 2.0 * w, 1.0 - 2.0 * u)
    };
    SurfaceParam {
        face: 4 * p.face + k,
        u: cu,
        v: cv,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A parameter names the same point of the flat base face before and after the split.
    #[test]
    fn child_parameters_name_the_same_point() {
        let base = TriMesh::new(
            vec![
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(1.0, 0.0, 0.0),
                DVec3::new(0.3, 1.0, 0.0),
                DVec3::new(1.2, 1.1, 0.0),
            ],
            vec![[0, 1, 2], [1, 3, 2]],
        );
        let topo = Topology::from_mesh(&base).expect("manifold");
        let (step, _) = loop_step_with_creases(&topo, &[]);
        // Linear positions: corners kept, odd vertices at edge midpoints.
        let mut fine = base.positions.clone();
        for (a, b, _) in topo.edges() {
            fine.push(0.5 * (base.positions[a as usize] + base.positions[b as usize]));
        }
        let at = |tris: &[[u32; 3]], pos: &[DVec3], p: &SurfaceParam| {
            let t = tris[p.face as usize];
            p.u * pos[t[0] as usize]
                + p.v * pos[t[1] as usize]
                + (1.0 - p.u - p.v) * pos[t[2] as usize]
        };
        let mut children_seen = [false; 4];
        for (i, (u, v)) in [
            (0.8, 0.1),
            (0.1, 0.7),
            (0.1, 0.15),
            (0.3, 0.3),
            (0.5, 0.5),
            (0.0, 0.0),
            (0.25, 0.45),
        ]
        .into_iter()
        .enumerate()
        {
            let p = SurfaceParam {
                face: (i % 2) as u32,
                u,
                v,
            };
            let c = child_param(p);
            children_seen[(c.face % 4) as usize] = true;
            assert!(c.u >= -1e-12 && c.v >= -1e-12 && c.u + c.v <= 1.0 + 1e-12);
            let before = at(&base.triangles, &base.positions, &p);
            let after = at(&step.triangles, &fine, &c);
            assert!((before - after).length() < 1e-12, "{p:?} -> {c:?}");
        }
        assert_eq!(children_seen, [true; 4]);
    }
}
