//! Where the shown surface misses fitted points, per Stanford scan: every fitted point more
//! than 1 mm from the shown (trimmed) tessellation is put in one class:
//! - `miss`: the surface itself passes farther than 1 mm from it (geometric error > 1 mm),
//! - `trim`: the untrimmed tessellation is within 1 mm of it, the trimming took that away;
//!   for those, how far the corners of the tessellation triangle at its parameter stand from
//!   it (a squeezed map makes one triangle of parameters span millimetres), and how far it
//!   lies from the rim of the data.
//!
//! Also the farthest shown vertex from the data.
//!
//!     cargo run --release --example coverage_gaps [-- DATA_DIR]

use glam::DVec2;
use rayon::prelude::*;
use rstar::RTree;
use std::collections::HashMap;
use std::path::PathBuf;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::output::{tessellate, Coverage, Tessellation};
use trispline::pipeline::scan::components::cleaned_components;
use trispline::pipeline::worker::{fit_patch, WorkerConfig};
use trispline::{DVec3, TriMesh};

const NEAR: f64 = 1e-3;

fn main() {
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let files = trispline::testdata::STANFORD_SCANS;
    let only = std::env::args().nth(2);
    for rel in files {
        if only.as_deref().is_some_and(|o| !rel.contains(o)) {
            continue;
        }
        let Ok(loaded) = read_mesh_file(&root.join(rel), &LoadOptions::default()) else {
            println!("{rel}: missing");
            continue;
        };
        report(rel, &loaded.mesh);
    }
}

fn as_mesh(t: &Tessellation) -> TriMesh {
    TriMesh::new(t.positions.clone(), t.triangles.clone())
}

fn report(rel: &str, mesh: &TriMesh) {
    let cfg = WorkerConfig::default();
    let piece = cleaned_components(&clean(mesh, &CleanOptions::default()))
        .into_iter()
        .next()
        .expect("a piece");
    let fitted = fit_patch(&piece, None, &cfg).expect("fits");
    let (fit, scan) = (&fitted.fit, fitted.scan.as_ref().expect("scan path"));
    let coverage = Coverage::of(fit, scan);
    let full = tessellate(fit, cfg.tessellation, None);
    let shown = tessellate(fit, cfg.tessellation, Some(&coverage));
    let (full_m, shown_m) = (as_mesh(&full), as_mesh(&shown));
    let (d_full, d_shown) = (MeshDistance::new(&full_m), MeshDistance::new(&shown_m));
    let reach = scan.trims.plan.max_bridge;
    // The tessellation triangle at each point's parameter.
    let plane: Vec<DVec2> = full.params.iter().map(|p| DVec2::new(p.u, p.v)).collect();
    let locator = ParamGrid::new(&full.triangles, &plane);
    let rim = rim_tree(&piece);
    let median_edge = median_edge(&full);
    let rows: Vec<(usize, f64, f64, f64, f64, f64)> = (0..fit.data.len())
        .into_par_iter()
        .filter_map(|k| {
            let p = fit.data[k];
            let ds = d_shown.distance(p).unwrap_or(f64::INFINITY);
            if ds <= NEAR {
                return None;
            }
            let df = d_full.distance(p).unwrap_or(f64::INFINITY);
            let q = DVec2::new(fit.params[k].u, fit.params[k].v);
            let t = locator.locate(q);
            let corners = full.triangles[t].map(|v| full.positions[v as usize]);
            let corner = corners.iter().map(|c| c.distance(p)).fold(0.0f64, f64::max);
            let size = (0..3)
                .map(|i| corners[i].distance(corners[(i + 1) % 3]))
                .fold(0.0f64, f64::max);
            let to_rim = rim
                .nearest_neighbor(&p.to_array())
                .map_or(f64::INFINITY, |r| DVec3::from_array(*r).distance(p));
            Some((k, df, fit.geometric_errors[k], corner, size, to_rim))
        })
        .collect();
    let n = fit.data.len();
    let miss = rows.iter().filter(|r| r.1 > NEAR).count();
    let trim: Vec<_> = rows.iter().filter(|r| r.1 <= NEAR).collect();
    let guard = trim.iter().filter(|r| r.3 > reach).count();
    let far_err = trim.iter().filter(|r| r.2 > reach).count();
    let near_rim = |lim: f64| trim.iter().filter(|r| r.5 <= lim).count();
    let squeezed = trim.iter().filter(|r| r.4 > 3.0 * median_edge).count();
    let data = MeshDistance::new(mesh);
    let farthest = shown
        .triangles
        .iter()
        .flatten()
        .map(|&v| v as usize)
        .collect::<Vec<_>>()
        .par_iter()
        .filter_map(|&v| data.distance(shown.positions[v]))
        .reduce(|| 0.0, f64::max);
    println!(
        "{rel}: n {n}, shown within 1mm {:.3}%, reach(max_bridge) {:.0} um, median tess edge {:.0} um, farthest shown {:.0} um",
        100.0 * (n - rows.len()) as f64 / n as f64,
        reach * 1e6,
        median_edge * 1e6,
        farthest * 1e6
    );
    println!(
        "  uncovered {} = miss {} (err>1mm; of all points with err>1mm: {}) + trim {}: corner>reach {}, err>reach {}, rim<=1mm {}, rim<=3mm {}, squeezed(>3x edge) {}",
        rows.len(),
        miss,
        fit.geometric_errors.iter().filter(|e| **e > NEAR).count(),
        trim.len(),
        guard,
        far_err,
        near_rim(1e-3),
        near_rim(3e-3),
        squeezed
    );
    let mut corner_hist: HashMap<u32, usize> = HashMap::new();
    for r in &trim {
        *corner_hist.entry((r.3 * 2e3).floor() as u32).or_default() += 1;
    }
    let mut h: Vec<_> = corner_hist.into_iter().collect();
    h.sort();
    println!(
        "  trim: farthest corner of its triangle (0.5 mm bins): {:?}",
        h.iter()
            .map(|(b, c)| format!("{:.1}-{:.1}:{c}", *b as f64 * 0.5, *b as f64 * 0.5 + 0.5))
            .collect::<Vec<_>>()
    );
    let mut e_hist: HashMap<u32, usize> = HashMap::new();
    for r in &trim {
        *e_hist.entry((r.2 * 1e4).floor() as u32).or_default() += 1;
    }
    let mut h: Vec<_> = e_hist.into_iter().collect();
    h.sort();
    println!(
        "  trim: own error (0.1 mm bins): {:?}",
        h.iter()
            .map(|(b, c)| format!("{:.1}:{c}", *b as f64 * 0.1))
            .collect::<Vec<_>>()
    );
}

/// The data's rim vertices (on an edge of one triangle).
fn rim_tree(m: &TriMesh) -> RTree<[f64; 3]> {
    let mut count: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &m.triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut rim: Vec<u32> = count
        .into_iter()
        .filter(|(_, c)| *c == 1)
        .flat_map(|((a, b), _)| [a, b])
        .collect();
    rim.sort_unstable();
    rim.dedup();
    RTree::bulk_load(
        rim.iter()
            .map(|&v| m.positions[v as usize].to_array())
            .collect(),
    )
}

fn median_edge(t: &Tessellation) -> f64 {
    let mut e: Vec<f64> = t
        .triangles
        .iter()
        .map(|tr| t.positions[tr[0] as usize].distance(t.positions[tr[1] as usize]))
        .collect();
    let k = e.len() / 2;
    if e.is_empty() {
        return 0.0;
    }
    *e.select_nth_unstable_by(k, f64::total_cmp).1
}

/// The tessellation triangle holding a parameter (or the one whose centroid is nearest).
struct ParamGrid<'a> {
    tris: &'a [[u32; 3]],
    plane: &'a [DVec2],
    cell: f64,
    buckets: HashMap<(i64, i64), Vec<usize>>,
}

impl<'a> ParamGrid<'a> {
    fn new(tris: &'a [[u32; 3]], plane: &'a [DVec2]) -> Self {
        let cell = tris
            .iter()
            .map(|t| plane[t[0] as usize].distance(plane[t[1] as usize]))
            .fold(0.0f64, f64::max)
            .max(1e-12);
        let mut buckets: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (k, t) in tris.iter().enumerate() {
            let c = t.iter().map(|&v| plane[v as usize]).sum::<DVec2>() / 3.0;
            buckets.entry(Self::key(c, cell)).or_default().push(k);
        }
        Self {
            tris,
            plane,
            cell,
            buckets,
        }
    }
    fn key(q: DVec2, cell: f64) -> (i64, i64) {
        ((q.x / cell).floor() as i64, (q.y / cell).floor() as i64)
    }
    fn locate(&self, q: DVec2) -> usize {
        let (cx, cy) = Self::key(q, self.cell);
        let mut best = (f64::MIN, 0usize);
        for dx in -2..=2 {
            for dy in -2..=2 {
                for &k in self.buckets.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                    let c = self.tris[k].map(|v| self.plane[v as usize]);
                    let det = (c[1] - c[0]).perp_dot(c[2] - c[0]);
                    if det == 0.0 {
                        continue;
                    }
                    let l1 = (q - c[0]).perp_dot(c[2] - c[0]) / det;
                    let l2 = (c[1] - c[0]).perp_dot(q - c[0]) / det;
                    let worst = (1.0 - l1 - l2).min(l1).min(l2);
                    if worst > best.0 {
                        best = (worst, k);
                    }
                }
            }
        }
        best.1
    }
}
