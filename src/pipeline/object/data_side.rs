//! What every fit of one data mesh reads of it besides its points (its topology summary,
//! rim, the band next to the rim, the nearest-point index), built once for all the fits
//! of a whole-object fit (the first, each refinement round's, the finishing rounds, the
//! stray repair) instead of once per fit.

use super::model::{ObjectError, ObjectOptions};
use super::rim::near_boundary_in;
use crate::mesh::distance::MeshDistance;
use crate::mesh::simplify::SurfaceTopology;
use crate::mesh::topology::Topology;
use crate::TriMesh;
use std::borrow::Cow;
use std::sync::OnceLock;

/// The data mesh of a whole-object fit and what its fits read of it.
pub(super) struct DataSide<'a> {
    pub mesh: &'a TriMesh,
    /// Its Euler characteristic, boundary loops and genus.
    pub topology: SurfaceTopology,
    /// Per vertex: on the data's boundary.
    pub on_rim: Vec<bool>,
    /// Per vertex: within `edge_rings` vertex rings of the boundary.
    near_edge: Vec<bool>,
    edge_rings: usize,
    /// Nearest points on the data, built on first use (a fit without surface samples and
    /// no stray repair never needs it).
    nearest: OnceLock<MeshDistance<'a>>,
}

impl<'a> DataSide<'a> {
    /// The data side of `mesh` whose topology `topo` is built already.
    pub(super) fn of_built(mesh: &'a TriMesh, topo: &Topology, opts: &ObjectOptions) -> Self {
        Self {
            mesh,
            topology: SurfaceTopology::of_built(mesh, topo),
            on_rim: near_boundary_in(topo, 0),
            near_edge: near_boundary_in(topo, opts.edge_rings),
            edge_rings: opts.edge_rings,
            nearest: OnceLock::new(),
        }
    }

    /// The data side of `mesh`; an error when it is no manifold.
    pub(super) fn new(mesh: &'a TriMesh, opts: &ObjectOptions) -> Result<Self, ObjectError> {
        let topo = Topology::from_mesh(mesh).map_err(ObjectError::NotManifold)?;
        Ok(Self::of_built(mesh, &topo, opts))
    }

    /// Per vertex: within `rings` vertex rings of the boundary. A band of another width
    /// than the fits' own builds the topology again: keeping it for that case held 68 MB
    /// through a 557k-point fit (about 7 % of its peak) that no fit of `fit_object` reads.
    pub(super) fn near_edge(&self, rings: usize) -> Cow<'_, [bool]> {
        if rings == self.edge_rings {
            return Cow::Borrowed(&self.near_edge);
        }
        match Topology::from_mesh(self.mesh) {
            Ok(topo) => Cow::Owned(near_boundary_in(&topo, rings)),
            // The side was built from this mesh's topology, so this does not happen; the
            // fits' own band is the nearest answer.
            Err(_) => Cow::Borrowed(&self.near_edge),
        }
    }

    /// Nearest points on the data mesh.
    pub(super) fn nearest(&self) -> &MeshDistance<'a> {
        self.nearest.get_or_init(|| MeshDistance::new(self.mesh))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata::octahedron;
    use glam::DVec3;

    /// An open fan: six triangles around a centre vertex, the six outer vertices on the
    /// boundary.
    fn hexagon() -> TriMesh {
        let mut positions = vec![DVec3::ZERO];
        positions.extend((0..6).map(|k| {
            let a = k as f64 * std::f64::consts::FRAC_PI_3;
            DVec3::new(a.cos(), a.sin(), 0.0)
        }));
        let triangles = (0..6u32).map(|k| [0, 1 + k, 1 + (k + 1) % 6]).collect();
        TriMesh::new(positions, triangles)
    }

    #[test]
    fn the_rim_and_bands_of_any_width_come_from_one_topology() {
        let mesh = hexagon();
        let opts = ObjectOptions {
            edge_rings: 0,
            ..Default::default()
        };
        let side = DataSide::new(&mesh, &opts).expect("a manifold fan");
        assert_eq!(side.topology.boundary_loops, 1);
        assert_eq!(side.on_rim, [false, true, true, true, true, true, true]);
        assert_eq!(*side.near_edge(0), side.on_rim[..]);
        assert!(
            side.near_edge(1).iter().all(|&b| b),
            "the centre is a ring in"
        );
        let point = DVec3::new(0.2, 0.1, 0.5);
        let nearest = side.nearest().closest(point).expect("a nearest point");
        assert!((nearest.point - DVec3::new(0.2, 0.1, 0.0)).length() < 1e-12);

        let (positions, triangles) = octahedron();
        let closed = TriMesh::new(positions, triangles);
        let side = DataSide::new(&closed, &opts).expect("a manifold octahedron");
        assert_eq!((side.topology.boundary_loops, side.topology.genus), (0, 0));
        assert!(side.on_rim.iter().all(|&b| !b));
    }
}
