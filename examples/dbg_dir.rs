use glam::DVec3;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::pipeline::scan::largest_component;
use trispline::remesh::planar::{folded_triangles, PlaneFrame};
fn main() {
    for path in std::env::args().skip(1) {
        let m = read_mesh_file(std::path::Path::new(&path), &LoadOptions::default())
            .unwrap()
            .mesh;
        let c = clean(&m, &CleanOptions::default());
        let (m, _) = largest_component(&c.mesh);
        let f = PlaneFrame::fit(&m).unwrap();
        let g = PlaneFrame::fit_least_folds(&m).unwrap();
        let count = |n: DVec3| {
            let e1 = n.any_orthonormal_vector();
            let e2 = n.cross(e1);
            let fr = PlaneFrame {
                origin: f.origin,
                e1,
                e2,
            };
            let plane: Vec<_> = m.positions.iter().map(|p| fr.project(*p)).collect();
            folded_triangles(&m.triangles, &plane).len()
        };
        println!(
            "{path}: mean normal folds {}, z folds {} -z {}, best {:?} folds {}",
            count(f.normal()),
            count(DVec3::Z),
            count(-DVec3::Z),
            g.normal(),
            count(g.normal())
        );
    }
}
