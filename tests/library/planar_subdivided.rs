//! B-patch and DMS fits of inputs with Loop subdivision connectivity (issue 24): the
//! domain is the coarse net's parameter triangulation after `fit.levels` inverse levels
//! (DMS: one domain triangle per coarse face; B-patch: the lattice's one triangle), and no
//! planar map of the fine mesh is made.

use glam::DVec3;
use trispline::mesh::loop_subdiv::subdivide;
use trispline::pipeline::worker::{fit_patch, FittedPatch, WorkerConfig};
use trispline::pipeline::{SurfaceKind, SurfaceModel};
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::TriMesh;

fn height(x: f64, y: f64) -> f64 {
    0.05 * (x * x - y * y) + 0.02 * (3.0 * x).sin() * y
}

/// A triangular lattice of `n` segments over the unit equilateral triangle, lifted by
/// `height`.
fn lattice_net(n: usize) -> TriMesh {
    let positions = lattice_points(n)
        .into_iter()
        .map(|(i, j)| {
            let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
            let (x, y) = (u + 0.5 * v, v * 3f64.sqrt() / 2.0);
            DVec3::new(x, y, height(x, y))
        })
        .collect();
    TriMesh::new(positions, lattice_triangles(n))
}

/// `n` triangles around a centre (valence n: irregular unless 6), lifted by `height`.
fn fan_net(n: usize) -> TriMesh {
    let mut positions = vec![DVec3::new(0.0, 0.0, height(0.0, 0.0))];
    let mut triangles = Vec::new();
    for k in 0..n {
        let a = k as f64 / n as f64 * std::f64::consts::TAU;
        let (x, y) = (a.cos(), a.sin());
        positions.push(DVec3::new(x, y, height(x, y)));
        triangles.push([0, 1 + k as u32, 1 + ((k + 1) % n) as u32]);
    }
    TriMesh::new(positions, triangles)
}

fn fitted(mesh: &TriMesh, kind: SurfaceKind, levels: usize) -> FittedPatch {
    let mut cfg = WorkerConfig::default();
    cfg.fit.surface = kind;
    cfg.fit.levels = levels;
    cfg.fit.method = trispline::fit::Method::Direct;
    fit_patch(mesh, None, &cfg).expect("fits")
}

/// The RMS distance of the data to the best plane: what the fits must beat by far.
fn plane_rms(points: &[DVec3]) -> f64 {
    // Heights are small against the extent: the plane z = a + b x + c y by least squares.
    let m = points.len() as f64;
    let mean = points.iter().sum::<DVec3>() / m;
    let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let d = *p - mean;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
        sxz += d.x * d.z;
        syz += d.y * d.z;
    }
    let det = sxx * syy - sxy * sxy;
    let (b, c) = ((sxz * syy - syz * sxy) / det, (syz * sxx - sxz * sxy) / det);
    let ss: f64 = points
        .iter()
        .map(|p| {
            let d = *p - mean;
            (d.z - b * d.x - c * d.y).powi(2)
        })
        .sum();
    (ss / m).sqrt()
}

#[test]
fn a_subdivided_input_fits_as_dms_over_its_coarse_net() {
    let coarse = fan_net(7);
    let mesh = subdivide(&coarse, 3).expect("manifold");
    let f = fitted(&mesh, SurfaceKind::Dms, 3);
    assert_eq!(f.levels, 3);
    assert!(f.scattered.is_none(), "no planar map of the fine mesh");
    let SurfaceModel::Dms(spline) = &f.fit.model else {
        panic!("a DMS model");
    };
    // One domain triangle per coarse face, the fine vertices on them.
    assert_eq!(spline.triangles().len(), coarse.triangles.len());
    assert_eq!(spline.vertices().len(), coarse.positions.len());
    assert_eq!(f.fit.params.len(), mesh.positions.len());
    assert!(f.fit.params.iter().all(|p| (p.face as usize) < 7));
    let (rms, plane) = (f.fit.geometric_rms(), plane_rms(&mesh.positions));
    println!(
        "dms on a 7-fan net, 3 levels: {} points, {} controls, rms {rms:.3e} (plane {plane:.3e}), max {:.3e}",
        mesh.positions.len(),
        f.fit.controls.len(),
        f.fit.geometric_max()
    );
    // Measured 0.062 of the plane's RMS (42 controls against 8 coarse vertices of a
    // Loop-subdivided net); parameters off their coarse faces would land near the plane's.
    assert!(
        rms < 0.15 * plane,
        "rms {rms:.3e} against the plane's {plane:.3e}"
    );
}

#[test]
fn a_subdivided_lattice_fits_as_one_bpatch_of_the_lattice_degree() {
    // The paper's B-patch case: a 12-segment lattice (91 points), two inverse levels give
    // the 3-segment net, so a cubic B-patch over its triangle.
    let mesh = subdivide(&lattice_net(3), 2).expect("manifold");
    assert_eq!(mesh.positions.len(), 91);
    let f = fitted(&mesh, SurfaceKind::Bpatch, 2);
    let SurfaceModel::BPatch(patch) = &f.fit.model else {
        panic!("a B-patch model");
    };
    assert_eq!(patch.degree(), 3);
    assert_eq!(f.fit.degree, 3);
    assert_eq!(f.fit.controls.len(), 10);
    let (rms, plane) = (f.fit.geometric_rms(), plane_rms(&mesh.positions));
    println!(
        "bpatch on a 3-lattice net, 2 levels: rms {rms:.3e} (plane {plane:.3e}), max {:.3e}",
        f.fit.geometric_max()
    );
    // Measured 0.070 of the plane's RMS: a cubic cannot follow the 12-segment Loop mesh.
    assert!(
        rms < 0.15 * plane,
        "rms {rms:.3e} against the plane's {plane:.3e}"
    );
}

#[test]
fn a_subdivided_net_that_is_no_lattice_gets_a_bpatch_around_its_map() {
    let mesh = subdivide(&fan_net(5), 2).expect("manifold");
    let f = fitted(&mesh, SurfaceKind::Bpatch, 2);
    let SurfaceModel::BPatch(patch) = &f.fit.model else {
        panic!("a B-patch model");
    };
    assert_eq!(patch.degree(), WorkerConfig::default().fit.bpatch.degree);
    assert_eq!(f.levels, 2);
    let (rms, plane) = (f.fit.geometric_rms(), plane_rms(&mesh.positions));
    println!(
        "bpatch on a 5-fan net, 2 levels: rms {rms:.3e} (plane {plane:.3e}), max {:.3e}",
        f.fit.geometric_max()
    );
    // Measured 0.012 of the plane's RMS.
    assert!(
        rms < 0.1 * plane,
        "rms {rms:.3e} against the plane's {plane:.3e}"
    );
}
