//! `object_table`'s diagnosis of one fit (`OBJ_DIAG`): the tessellation's chord error,
//! where the surface strays, the data's facets, the rounds, and where the squared error
//! lies (the rim band, irregular patches, crease faces, the worst points and faces)
//! beside the data's own noise.

use super::{rms_max, tessellation_at, TESS};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::object::ObjectFit;
use trispline::surface::TriSurface;
use trispline::{DVec3, TriMesh};

/// The control faces whose patches stray farthest from the data, each with the foot
/// points it holds and its valences: are they faces the data left (few feet), rim faces,
/// or irregular ones?
fn stray_faces(fit: &ObjectFit, tess: &TriMesh) {
    let per_face = (TESS + 1) * (TESS + 2) / 2;
    let md = MeshDistance::new(&fit.component);
    let mut feet = vec![0usize; fit.surface.domain_face_count()];
    for p in &fit.params {
        feet[p.face as usize] += 1;
    }
    let control = fit.control_mesh();
    let Ok(topo) = trispline::mesh::topology::Topology::from_mesh(&control) else {
        return;
    };
    let mut worst: Vec<(f64, usize)> = (0..control.triangles.len())
        .map(|f| {
            let d = tess.positions[f * per_face..(f + 1) * per_face]
                .iter()
                .map(|p| md.distance(*p).unwrap_or(f64::INFINITY))
                .fold(0.0, f64::max);
            (d, f)
        })
        .collect();
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    let diag = fit.component.bounds_diagonal();
    let few = feet.iter().filter(|&&c| c < 4).count();
    let over: usize = worst.iter().filter(|w| w.0 > 0.005 * diag).count();
    let list: Vec<String> = worst
        .iter()
        .take(6)
        .map(|&(d, f)| {
            let t = control.triangles[f];
            let val: Vec<String> = t
                .iter()
                .map(|&v| {
                    let b = if topo.boundary[v as usize] { "b" } else { "" };
                    format!("{}{b}", topo.valence(v))
                })
                .collect();
            format!(
                "{:.3}% f{f} feet {} val {}",
                100.0 * d / diag,
                feet[f],
                val.join("/")
            )
        })
        .collect();
    println!(
        "  stray: {over} faces over 0.5 %, {few} faces with < 4 feet; worst: {}",
        list.join(", ")
    );
}

/// Where the RMS comes from (`OBJ_DIAG` set): the chord error of the measuring
/// tessellation, the rounds, and how the squared error is spread over the rim band, the
/// irregular patches, the worst points and faces, against the data's own noise.
pub fn diagnose(fit: &ObjectFit, tess_rms: f64) {
    let fine = tessellation_at(fit, 3 * TESS);
    let (fine_rms, _) = rms_max(&fit.data, &fine);
    println!(
        "  chord: tess{} rms {:.4e}, tess{} rms {:.4e}, foot-point rms {:.4e}",
        TESS,
        tess_rms,
        3 * TESS,
        fine_rms,
        fit.rms
    );
    stray_faces(fit, &tessellation_at(fit, TESS));
    if let Some(stray) = fit.stray {
        println!(
            "  the fit's own stray measure: {:.3}% of the diagonal",
            100.0 * stray / fit.component.bounds_diagonal()
        );
    }
    facet_sagitta(&fit.component);
    let rounds: Vec<String> = fit
        .rounds
        .iter()
        .map(|r| format!("{:.4e}", r.rms))
        .collect();
    println!("  rounds (last fit): {}", rounds.join(" "));
    if let Ok(file) = std::env::var("OBJ_DUMP_DIST") {
        let mut out = String::new();
        for (p, d) in fit.data.iter().zip(&fit.distances) {
            out.push_str(&format!("{} {} {} {d}\n", p.x, p.y, p.z));
        }
        if let Err(e) = std::fs::write(&file, out) {
            println!("  could not write {file}: {e}");
        }
    }
    let sq: Vec<f64> = fit.distances.iter().map(|d| d * d).collect();
    let total: f64 = sq.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let share_where = |mark: &dyn Fn(usize) -> bool| {
        let (mut count, mut sum) = (0usize, 0.0);
        for (i, s) in sq.iter().enumerate() {
            if mark(i) {
                count += 1;
                sum += s;
            }
        }
        let n = fit.data.len().max(1) as f64;
        let rms = (sum / count.max(1) as f64).sqrt();
        format!(
            "{:.1}% of points, {:.1}% of sq error, rms {:.3e}",
            100.0 * count as f64 / n,
            100.0 * sum / total,
            rms
        )
    };
    if let Ok(topo) = trispline::mesh::topology::Topology::from_mesh(&fit.component) {
        let mut near = topo.boundary.clone();
        for _ in 0..3 {
            let prev = near.clone();
            for (v, _) in prev.iter().enumerate().filter(|e| *e.1) {
                for &x in topo.ring(v as u32) {
                    near[x as usize] = true;
                }
            }
        }
        println!("  rim band (3 rings): {}", share_where(&|i| near[i]));
        let noise = local_noise(&fit.component, &topo);
        println!(
            "  data noise (vertex to a quadric of its 2-ring): median {:.3e}, rms {:.3e}",
            noise.0, noise.1
        );
    }
    let irregular = |i: usize| !fit.surface.is_regular_face(fit.params[i].face as usize);
    println!("  on irregular patches: {}", share_where(&irregular));
    let mut on_crease = vec![false; fit.controls.len()];
    for &[a, b] in fit.surface.crease_edges() {
        on_crease[a as usize] = true;
        on_crease[b as usize] = true;
    }
    let faces = fit.surface.faces();
    let creased = |i: usize| {
        faces[fit.params[i].face as usize]
            .iter()
            .any(|&v| on_crease[v as usize])
    };
    println!("  on faces with a crease vertex: {}", share_where(&creased));
    let mut sorted = sq.clone();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let top = |f: f64| {
        let k = ((f * sorted.len() as f64).ceil() as usize).min(sorted.len());
        100.0 * sorted[..k].iter().sum::<f64>() / total
    };
    let mut per_face = vec![0.0; fit.surface.domain_face_count()];
    for (p, s) in fit.params.iter().zip(&sq) {
        per_face[p.face as usize] += s;
    }
    per_face.sort_by(|a, b| b.total_cmp(a));
    let top_faces = |f: f64| {
        let k = ((f * per_face.len() as f64).ceil() as usize).min(per_face.len());
        100.0 * per_face[..k].iter().sum::<f64>() / total
    };
    let median = {
        let mut d = fit.distances.clone();
        d.sort_by(|a, b| a.total_cmp(b));
        d[d.len() / 2]
    };
    println!(
        "  concentration: worst 1% points {:.1}%, 5% {:.1}% of sq error; worst 5% faces {:.1}%, 20% {:.1}%; median distance {:.3e}",
        top(0.01),
        top(0.05),
        top_faces(0.05),
        top_faces(0.2),
        median
    );
}

/// Median and RMS over the vertices of the distance of each vertex to the least-squares
/// quadric height field over its two rings (in the frame of its area-weighted normal):
/// the data's own roughness, which no smooth surface fits below.
fn local_noise(mesh: &TriMesh, topo: &trispline::mesh::topology::Topology) -> (f64, f64) {
    let mut normals = vec![DVec3::ZERO; mesh.positions.len()];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
        let n = (b - a).cross(c - a);
        for &v in t {
            normals[v as usize] += n;
        }
    }
    let mut res = Vec::new();
    for (v, normal) in normals.iter().enumerate() {
        let Some(n) = normal.try_normalize() else {
            continue;
        };
        let mut ring: Vec<u32> = topo.ring(v as u32).to_vec();
        for &x in topo.ring(v as u32) {
            ring.extend_from_slice(topo.ring(x));
        }
        ring.sort_unstable();
        ring.dedup();
        ring.retain(|&x| x as usize != v);
        if ring.len() < 9 {
            continue;
        }
        let o = mesh.positions[v];
        let e1 = n.any_orthonormal_vector();
        let e2 = n.cross(e1);
        // Normal equations of z = a x^2 + b xy + c y^2 + d x + e y + f (the vertex left out).
        let mut ata = [[0.0f64; 6]; 6];
        let mut atb = [0.0f64; 6];
        let mut scale = 0.0f64;
        for &x in &ring {
            let d = mesh.positions[x as usize] - o;
            scale = scale.max(d.length());
        }
        let s = scale.max(f64::MIN_POSITIVE);
        for &x in &ring {
            let d = (mesh.positions[x as usize] - o) / s;
            let (px, py, pz) = (d.dot(e1), d.dot(e2), d.dot(n));
            let row = [px * px, px * py, py * py, px, py, 1.0];
            for i in 0..6 {
                atb[i] += row[i] * pz;
                for j in 0..6 {
                    ata[i][j] += row[i] * row[j];
                }
            }
        }
        let Some(c) = solve6(ata, atb) else { continue };
        res.push((c[5] * s).abs());
    }
    if res.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let rms = (res.iter().map(|r| r * r).sum::<f64>() / res.len() as f64).sqrt();
    res.sort_by(|a, b| a.total_cmp(b));
    (res[res.len() / 2], rms)
}

/// Gaussian elimination with partial pivoting of a 6x6 system.
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    for col in 0..6 {
        let piv = (col..6).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..6 {
            let f = a[r][col] / a[col][col];
            let pivot_row = a[col];
            for (x, p) in a[r].iter_mut().zip(pivot_row).skip(col) {
                *x -= f * p;
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 6];
    for r in (0..6).rev() {
        let s: f64 = (r + 1..6).map(|c| a[r][c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

/// How far any smooth surface through the data's vertices must leave its flat facets:
/// per data edge, the sagitta of the circular arc between its ends that meets their
/// vertex normals, L / 2 tan(theta / 4). The stray (surface to data mesh) of a coarse mesh
/// measures its facets as much as the fit; across a crease the estimate means nothing.
fn facet_sagitta(data: &TriMesh) {
    let normals = data.vertex_normals();
    let p = &data.positions;
    let mut sagitta: Vec<f64> = data
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k] as usize, t[(k + 1) % 3] as usize)))
        .map(|(a, b)| {
            let theta = normals[a].dot(normals[b]).clamp(-1.0, 1.0).acos().min(3.0);
            0.5 * p[a].distance(p[b]) * (0.25 * theta).tan()
        })
        .collect();
    if sagitta.is_empty() {
        return;
    }
    sagitta.sort_by(f64::total_cmp);
    let pct = |q: f64| {
        let k = ((sagitta.len() - 1) as f64 * q).round() as usize;
        100.0 * sagitta[k] / data.bounds_diagonal()
    };
    println!(
        "  data facets: edge sagitta between vertex normals, % of the diagonal: max {:.3}, p99.9 {:.3}, p99 {:.3}, median {:.4}",
        pct(1.0),
        pct(0.999),
        pct(0.99),
        pct(0.5)
    );
}
