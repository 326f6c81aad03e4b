//! Sharp edges in whole-object fits: generated CAD-like parts (a box, a capped cylinder,
//! a box with a shallow gable roof)
//! keep their edges as crease edges of the Loop limit surface, and compare with the
//! quadric-decimated mesh of as many vertices; smooth shared models get few or no creases.

use glam::DVec3;
use std::collections::HashMap;
use trispline::io::surface_json::{parse_surface_json, SurfaceDescription};
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::crease::{detect_creases, CreaseOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::simplify::baseline::decimation_baselines;
use trispline::mesh::topology::Topology;
use trispline::pipeline::object::{fit_object, ObjectFit, ObjectOptions};
use trispline::pipeline::worker::{run_patch, Domain, WorkerConfig};
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::testdata::shared_data;
use trispline::TriMesh;

/// Vertices shared by position (exact: generated coordinates are computed the same way
/// wherever a vertex recurs).
struct Builder {
    ids: HashMap<[u64; 3], u32>,
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
}

impl Builder {
    fn new() -> Self {
        Self {
            ids: HashMap::new(),
            positions: Vec::new(),
            triangles: Vec::new(),
        }
    }

    fn id(&mut self, p: DVec3) -> u32 {
        // Rounded to 1e-9 so that one point computed along two routes is one vertex.
        let key = [p.x, p.y, p.z].map(|c| ((c * 1e9).round() as i64) as u64);
        *self.ids.entry(key).or_insert_with(|| {
            self.positions.push(p);
            (self.positions.len() - 1) as u32
        })
    }

    fn finish(self) -> TriMesh {
        TriMesh::new(self.positions, self.triangles)
    }
}

/// A box of `size` with a grid of about `spacing` on every face, outward oriented.
fn box_mesh(size: DVec3, spacing: f64) -> TriMesh {
    let mut b = Builder::new();
    for axis in 0..3 {
        for side in [0.0, 1.0] {
            let (a, c) = ((axis + 1) % 3, (axis + 2) % 3);
            let (a, c) = if side == 1.0 { (a, c) } else { (c, a) };
            let (na, nc) = (
                (size[a] / spacing).round().max(1.0) as usize,
                (size[c] / spacing).round().max(1.0) as usize,
            );
            let at = |i: usize, j: usize| {
                let mut p = DVec3::ZERO;
                p[axis] = side * size[axis];
                p[a] = size[a] * i as f64 / na as f64;
                p[c] = size[c] * j as f64 / nc as f64;
                p
            };
            for i in 0..na {
                for j in 0..nc {
                    let q =
                        [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)].map(|p| b.id(p));
                    // One diagonal direction: valence 6 inside.
                    b.triangles.push([q[0], q[1], q[2]]);
                    b.triangles.push([q[0], q[2], q[3]]);
                }
            }
        }
    }
    b.finish()
}

/// Triangles between two concentric, angle-sorted rings (`inner` may be one point).
fn stitch(b: &mut Builder, outer: &[DVec3], inner: &[DVec3], flip: bool) {
    let (no, ni) = (outer.len(), inner.len());
    let (mut i, mut j) = (0usize, 0usize);
    let push = |t: [DVec3; 3], b: &mut Builder| {
        let t = if flip { [t[0], t[2], t[1]] } else { t };
        let ids = t.map(|p| b.id(p));
        b.triangles.push(ids);
    };
    while i < no || j < ni {
        // Advance on the ring whose next point comes first in angle.
        let next_o = (i + 1) as f64 / no as f64;
        let next_i = (j + 1) as f64 / ni as f64;
        if ni == 1 && i == no {
            break;
        }
        if j >= ni || (i < no && next_o <= next_i) {
            push([outer[i % no], outer[(i + 1) % no], inner[j % ni]], b);
            i += 1;
        } else {
            push([outer[i % no], inner[(j + 1) % ni], inner[j % ni]], b);
            j += 1;
        }
    }
}

/// A cylinder (axis z, `radius`, `height`) with flat caps, `around` points on a circle,
/// side rows of about the same spacing, caps in rings of decreasing point counts.
fn capped_cylinder(radius: f64, height: f64, around: usize) -> TriMesh {
    let mut b = Builder::new();
    let spacing = std::f64::consts::TAU * radius / around as f64;
    let ring = |r: f64, z: f64, n: usize, twist: f64| -> Vec<DVec3> {
        (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * (k as f64 + twist) / n as f64;
                DVec3::new(r * t.cos(), r * t.sin(), z)
            })
            .collect()
    };
    let rows = (height / (spacing * 0.866)).round().max(1.0) as usize;
    for j in 0..rows {
        let (z0, z1) = (
            height * j as f64 / rows as f64,
            height * (j + 1) as f64 / rows as f64,
        );
        let lower = ring(radius, z0, around, 0.5 * (j % 2) as f64);
        let upper = ring(radius, z1, around, 0.5 * ((j + 1) % 2) as f64);
        stitch(&mut b, &lower, &upper, false);
    }
    // Caps: rings inwards, point counts proportional to the radius.
    let rings = (radius / spacing).round().max(1.0) as usize;
    for (z, flip) in [(0.0, true), (height, false)] {
        let twist = if z == 0.0 {
            0.0
        } else {
            0.5 * (rows % 2) as f64
        };
        let mut outer = ring(radius, z, around, twist);
        for k in (0..rings).rev() {
            let r = radius * k as f64 / rings as f64;
            let inner = if k == 0 {
                vec![DVec3::new(0.0, 0.0, z)]
            } else {
                ring(r, z, ((around * k) / rings).max(6), 0.0)
            };
            stitch(&mut b, &outer, &inner, flip);
            outer = inner;
        }
    }
    b.finish()
}

/// Each control face's limit patch on a lattice of `k` segments per edge (shared edges
/// repeated: only distances are measured on it).
fn tessellation(fit: &ObjectFit, k: usize) -> TriMesh {
    let evaluate = fit.surface.evaluator(&fit.controls);
    let index = |i: usize, j: usize| j * (2 * k + 3 - j) / 2 + i;
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for f in 0..fit.surface.domain_face_count() {
        let base = positions.len() as u32;
        for j in 0..=k {
            for i in 0..=k - j {
                let (u, v) = (i as f64 / k as f64, j as f64 / k as f64);
                positions.push(
                    evaluate(SurfaceParam {
                        face: f as u32,
                        u,
                        v,
                    })
                    .position,
                );
            }
        }
        for j in 0..k {
            for i in 0..k - j {
                let (a, b, c) = (index(i, j), index(i + 1, j), index(i, j + 1));
                triangles.push([a, b, c].map(|x| base + x as u32));
                if i + j + 1 < k {
                    triangles.push([b, index(i + 1, j + 1), c].map(|x| base + x as u32));
                }
            }
        }
    }
    TriMesh::new(positions, triangles)
}

fn rms_max(points: &[DVec3], mesh: &TriMesh) -> (f64, f64) {
    let md = MeshDistance::new(mesh);
    let (mut sum, mut max) = (0.0, 0.0f64);
    for p in points {
        let d = md.distance(*p).unwrap_or(f64::INFINITY);
        sum += d * d;
        max = max.max(d);
    }
    ((sum / points.len().max(1) as f64).sqrt(), max)
}

/// The angle (degrees) between the limit surface's normals on the two sides of each crease
/// edge, at its midpoint.
fn crease_normal_angles(fit: &ObjectFit) -> Vec<f64> {
    let faces = fit.surface.faces();
    let evaluate = fit.surface.evaluator(&fit.controls);
    fit.surface
        .crease_edges()
        .iter()
        .map(|&[a, b]| {
            let normals: Vec<DVec3> = faces
                .iter()
                .enumerate()
                .filter(|(_, t)| t.contains(&a) && t.contains(&b))
                .map(|(f, t)| {
                    let mut bary = [0.0; 3];
                    for (k, &c) in t.iter().enumerate() {
                        if c == a || c == b {
                            bary[k] = 0.5;
                        }
                    }
                    let d = evaluate(SurfaceParam {
                        face: f as u32,
                        u: bary[0],
                        v: bary[1],
                    });
                    d.du.cross(d.dv)
                })
                .collect();
            assert_eq!(normals.len(), 2, "a crease edge has two faces");
            normals[0].angle_between(normals[1]).to_degrees()
        })
        .collect()
}

struct Comparison {
    creases: usize,
    rms: f64,
    max: f64,
    qem_rms: f64,
    qem_max: f64,
}

fn compare_with_qem(fit: &ObjectFit) -> Comparison {
    let (rms, max) = rms_max(&fit.data, &tessellation(fit, 8));
    // The baseline is the better of the guarded and the plain decimation.
    let (qem_rms, qem_max) = decimation_baselines(&fit.component, fit.controls.len())
        .into_iter()
        .map(|qem| {
            let qem = qem.expect("the decimation baseline");
            assert_eq!(qem.mesh.positions.len(), fit.controls.len());
            rms_max(&fit.data, &qem.mesh)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .expect("two baselines");
    Comparison {
        creases: fit.surface.crease_edges().len(),
        rms,
        max,
        qem_rms,
        qem_max,
    }
}

fn no_creases() -> ObjectOptions {
    ObjectOptions {
        crease: CreaseOptions {
            angle_deg: 0.0,
            ..CreaseOptions::default()
        },
        ..ObjectOptions::default()
    }
}

#[test]
fn a_box_keeps_its_right_angles_where_a_smooth_fit_rounds_them() {
    let size = DVec3::new(0.1, 0.07, 0.05);
    let mesh = box_mesh(size, 0.0025);
    let diag = size.length();
    let fit = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    let c = compare_with_qem(&fit);
    let angles = crease_normal_angles(&fit);
    assert!(c.creases >= 12, "{} crease edges", c.creases);
    let worst = angles
        .iter()
        .map(|a| (a - 90.0).abs())
        .fold(0.0f64, f64::max);
    let mean = angles.iter().sum::<f64>() / angles.len() as f64;
    assert!(
        worst < 3.0,
        "normals across the box's edges {worst} degrees off 90"
    );
    let smooth = fit_object(&mesh, &no_creases()).expect("fitted");
    let s = compare_with_qem(&smooth);
    assert_eq!(s.creases, 0);
    assert!(
        c.max < 0.25 * s.max,
        "creased max {} vs rounded {}",
        c.max,
        s.max
    );
    assert!(
        c.max < 1e-3 * diag,
        "creased max {} of diagonal {diag}",
        c.max
    );
    println!(
        "box {} points, {} controls, {} crease edges: normal angle mean {mean:.3} worst |a - 90| {worst:.3} deg; \
         rms {:.3e} max {:.3e} (rounded: rms {:.3e} max {:.3e}; QEM rms {:.3e} max {:.3e})",
        fit.data.len(),
        fit.controls.len(),
        c.creases,
        c.rms,
        c.max,
        s.rms,
        s.max,
        c.qem_rms,
        c.qem_max
    );
}

#[test]
fn a_capped_cylinder_beats_the_decimated_mesh_of_the_same_size() {
    let (radius, height) = (0.03, 0.05);
    let mesh = capped_cylinder(radius, height, 120);
    let fit = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    let c = compare_with_qem(&fit);
    let angles = crease_normal_angles(&fit);
    let worst = angles
        .iter()
        .map(|a| (a - 90.0).abs())
        .fold(0.0f64, f64::max);
    println!(
        "cylinder {} points, {} controls, {} crease edges (worst |angle - 90| {worst:.2} deg): \
         rms {:.3e} max {:.3e}; QEM rms {:.3e} max {:.3e}",
        fit.data.len(),
        fit.controls.len(),
        c.creases,
        c.rms,
        c.max,
        c.qem_rms,
        c.qem_max
    );
    assert!(c.creases >= 12, "the two rims are creases ({})", c.creases);
    assert!(worst < 5.0, "rim normals {worst} degrees off 90");
    assert!(c.rms <= c.qem_rms, "rms {} vs QEM {}", c.rms, c.qem_rms);
    assert!(
        c.max <= 1.5 * c.qem_max,
        "max {} vs QEM {}",
        c.max,
        c.qem_max
    );
}

fn crease_count(relative: &str) -> Option<(usize, usize)> {
    let path = shared_data(relative)?;
    let mesh = read_mesh_file(&path, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{relative}: {e}"))
        .mesh;
    let cleaned = clean(&mesh, &CleanOptions::default()).mesh;
    let topo = Topology::from_mesh(&cleaned).expect("a cleaned mesh is manifold");
    let edges = topo.edges().len();
    Some((
        detect_creases(&cleaned, &topo, &CreaseOptions::default()).len(),
        edges,
    ))
}

#[test]
fn smooth_models_get_no_spurious_creases_at_the_default_angle() {
    for name in ["models/fertility.off", "models/bun_zipper.ply"] {
        let Some((creases, edges)) = crease_count(name) else {
            eprintln!("{name} missing: skipped");
            continue;
        };
        println!("{name}: {creases} crease edges of {edges} at the default angle");
        assert_eq!(creases, 0, "{name}: {creases} of {edges} edges tagged");
    }
}

#[test]
fn surface_json_and_the_report_carry_the_creases_and_warm_starts_keep_them() {
    let mesh = box_mesh(DVec3::new(0.06, 0.05, 0.04), 0.004);
    let mut cfg = WorkerConfig::default();
    cfg.fit.domain = Domain::Auto;
    cfg.fit.correction.rounds = 3;
    cfg.tessellation = 8;
    let first = run_patch(&mesh, None, &cfg).expect("a box fits");
    let s = &first.surface;
    assert_eq!(s["layout"], "mesh");
    let written: Vec<[u32; 2]> =
        serde_json::from_value(s["crease_edges"].clone()).expect("crease_edges is a list of pairs");
    assert!(written.len() >= 12, "{} crease edges", written.len());
    assert_eq!(first.report["object"]["crease_edges"], written.len());
    let bytes = serde_json::to_vec(s).expect("json");
    match parse_surface_json(&bytes, "box").expect("reads back") {
        SurfaceDescription::LoopMesh { surface, .. } => {
            assert_eq!(surface.crease_edges(), &written[..]);
        }
        _ => panic!("layout mesh reads back as another kind"),
    }
    // The next version starts from the creased control mesh.
    let second = run_patch(&mesh, Some(&first.warm), &cfg).expect("fits warm");
    assert_eq!(second.report["object"]["warm"]["used"], true);
    assert_eq!(second.surface["crease_edges"], s["crease_edges"]);
    // Creases off: none written.
    cfg.fit.crease_angle_deg = 0.0;
    let off = run_patch(&mesh, None, &cfg).expect("fits");
    assert_eq!(off.surface["crease_edges"], serde_json::json!([]));
    assert_eq!(off.report["object"]["crease_edges"], 0);
}

/// A box whose top is a gable roof: two planes pitched by `pitch_deg` meeting at a ridge
/// over the middle of its x extent (the ridge turns by twice the pitch, the eaves by 90
/// degrees less the pitch).
fn gabled_box(size: DVec3, spacing: f64, pitch_deg: f64) -> TriMesh {
    let mut mesh = box_mesh(size, spacing);
    let slope = pitch_deg.to_radians().tan();
    let half = 0.5 * size.x;
    for p in &mut mesh.positions {
        if (p.y - size.y).abs() < 1e-12 {
            p.y += slope * (half - (p.x - half).abs());
        }
    }
    mesh
}

#[test]
fn a_shallow_roof_ridge_stays_sharp_by_the_relative_rule() {
    let size = DVec3::new(0.1, 0.06, 0.08);
    // The ridge turns by 40 degrees, under the 60-degree angle; the eaves by 70.
    let mesh = gabled_box(size, 0.0025, 20.0);
    // The smooth surface's creases are the subject: the part is polyhedral, so the
    // faceted candidate (`object_faceted`) would match it too, with the ridge's three
    // decimated edges.
    let smooth_only = ObjectOptions {
        faceted_candidate: false,
        ..ObjectOptions::default()
    };
    let fit = fit_object(&mesh, &smooth_only).expect("fitted");
    let c = compare_with_qem(&fit);
    let on_ridge = |v: u32| {
        let p = fit.controls[v as usize];
        (p.x - 0.5 * size.x).abs() < 1e-3 && p.y > size.y + 1e-3
    };
    let ridge: Vec<usize> = fit
        .surface
        .crease_edges()
        .iter()
        .enumerate()
        .filter(|(_, &[a, b])| on_ridge(a) && on_ridge(b))
        .map(|(k, _)| k)
        .collect();
    let angles = crease_normal_angles(&fit);
    let worst = ridge
        .iter()
        .map(|&k| (angles[k] - 40.0).abs())
        .fold(0.0f64, f64::max);
    let angle_only = fit_object(
        &mesh,
        &ObjectOptions {
            crease: CreaseOptions {
                relative_ratio: 0.0,
                ..CreaseOptions::default()
            },
            ..smooth_only.clone()
        },
    )
    .expect("fitted");
    let a = compare_with_qem(&angle_only);
    println!(
        "gabled box {} points, {} controls, {} crease edges ({} on the ridge, worst |angle - 40| \
         {worst:.2} deg): rms {:.3e} max {:.3e}; angle rule only: {} crease edges, rms {:.3e} \
         max {:.3e}; QEM rms {:.3e} max {:.3e}",
        fit.data.len(),
        fit.controls.len(),
        c.creases,
        ridge.len(),
        c.rms,
        c.max,
        a.creases,
        a.rms,
        a.max,
        c.qem_rms,
        c.qem_max
    );
    assert!(
        ridge.len() >= 4,
        "the ridge is a crease ({} edges)",
        ridge.len()
    );
    assert!(
        worst < 3.0,
        "normals across the ridge {worst} degrees off 40"
    );
    // The part is polyhedral, so the decimation is exact (its RMS is rounding): the
    // comparison is with the diagonal and with the angle rule alone.
    let diag = size.length();
    assert!(c.max < 1e-4 * diag, "max {} of diagonal {diag}", c.max);
    assert!(
        c.rms < 0.5 * a.rms,
        "rms {} vs {} with the angle only",
        c.rms,
        a.rms
    );
}

/// A faceted part whose flat sides only long thin faces keep: the simplification's
/// triangle-quality guard would stop it far above the budget, so it gives way, and the fit
/// holds the budget (plus the stray repair's tenth) while matching the part at least as
/// well as the plain quadric decimation with as many vertices (the guarded one stalls
/// too).
#[test]
fn a_faceted_part_keeps_its_budget_where_the_quality_guard_would_stall() {
    let (mesh, _) = trispline::testdata::faceted_prism(8, 60, 2);
    let opts = ObjectOptions {
        target_controls: Some(40),
        ..ObjectOptions::default()
    };
    let fit = fit_object(&mesh, &opts).expect("fitted");
    let (rms, max) = rms_max(&fit.data, &tessellation(&fit, 8));
    let [guarded, plain] = decimation_baselines(&fit.component, fit.controls.len())
        .map(|qem| qem.expect("the decimation baseline").mesh);
    let (qem_rms, qem_max) = rms_max(&fit.data, &plain);
    println!(
        "faceted prism {} points: {} controls, {} crease edges, guard dropped {}; RMS {rms:.3e} max {max:.3e}; plain QEM ({} vertices) RMS {qem_rms:.3e} max {qem_max:.3e}; guarded QEM {} vertices",
        fit.data.len(),
        fit.controls.len(),
        fit.surface.crease_edges().len(),
        fit.layout.quality_guard_dropped,
        plain.positions.len(),
        guarded.positions.len(),
    );
    assert!(fit.layout.quality_guard_dropped, "the guard kept");
    assert!(fit.controls.len() <= 44, "{} controls", fit.controls.len());
    assert_eq!(plain.positions.len(), fit.controls.len());
    // Both can be exact: rounding aside, no worse.
    let floor = 1e-9;
    assert!(rms <= qem_rms.max(floor), "RMS {rms} vs QEM {qem_rms}");
    assert!(
        max <= 1.5 * qem_max.max(floor),
        "max {max} vs QEM {qem_max}"
    );
}
