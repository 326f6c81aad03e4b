//! `trispline fit`: one patch in, `surface.json`, `surface.glb` and `report.json` out.

use super::progress::Progress;
use crate::fit::{FitStatus, Method};
use crate::io::{read_mesh_file, write_atomic, write_atomic_group, LoadOptions};
use crate::mesh::inverse::InverseMethod;
use crate::pipeline::scan::components::ComponentMode;
use crate::pipeline::scan::{BezierLayout, Correction, CorrectionConfig, ScanConfig};
use crate::pipeline::scattered::{BPatchConfig, DmsConfig};
use crate::pipeline::worker::{
    run_input_with, BudgetConfig, ComponentsConfig, Domain, FitConfig, PatchOutputs, WorkerConfig,
    DEFAULT_CREASE_ANGLE_DEG, DEFAULT_CREASE_RELATIVE_RATIO, DEFAULT_TESSELLATION,
};
use crate::pipeline::SurfaceKind;
use anyhow::Context;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::str::FromStr;

/// A parser for a core enum spelled by fixed names: `--help` lists them, and the core needs
/// no command-line library.
fn named<T>(names: impl IntoIterator<Item = &'static str>) -> impl TypedValueParser<Value = T>
where
    T: FromStr + Clone + Send + Sync + 'static,
    T::Err: std::error::Error + Send + Sync + 'static,
{
    PossibleValuesParser::new(names).try_map(|s| s.parse::<T>())
}

/// Arguments of `trispline fit`.
#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// The input mesh: a disk-like scan patch (any connectivity), a whole object (closed,
    /// holed, any genus) or a mesh with Loop subdivision connectivity (fitted exactly); or a
    /// point cloud (.xyz, .pts, .pcd, vertices-only .ply) of a scan that is a height field
    /// over some plane, triangulated and fitted as a scan.
    pub input: PathBuf,
    /// The surface fitted: `loop` (scans: a Loop surface over a grid; subdivided inputs: the
    /// Loop limit surface of their coarse net; whole objects: the Loop limit surface of a
    /// control mesh simplified from the data) or `bezier` (scans: one quartic Bezier patch
    /// per grid cell; subdivided inputs: one patch over a lattice-shaped coarse net; whole
    /// objects are fitted with `loop` whatever is asked), `bpatch` (one B-patch of degree
    /// --bpatch-degree over a triangle around the planar map) or `dms` (a DMS triangular
    /// B-spline of degree --dms-degree over grid triangles of the planar map); the last two
    /// map every input to the plane, subdivided ones too.
    #[arg(long, value_parser = named::<SurfaceKind>(SurfaceKind::NAMES.iter().copied()), default_value = "loop")]
    pub surface: SurfaceKind,
    /// Inputs without subdivision connectivity: `auto` (disk-like scans on a grid over their
    /// planar map; closed, higher-genus and nearly closed inputs on a control mesh), `grid`
    /// (always the planar map) or `mesh` (always a control mesh simplified from the data,
    /// subdivided inputs too).
    #[arg(long, value_parser = named::<Domain>(Domain::NAMES.iter().copied()), default_value = "auto")]
    pub domain: Domain,
    /// Levels of inverse subdivision (subdivided inputs: the depth of their connectivity;
    /// scans: the resampling depth of the initial net).
    #[arg(long, default_value_t = 2)]
    pub levels: usize,
    /// Inputs with subdivision connectivity: when the budget is not met, refit with one level
    /// less (4x control points) down to this floor.
    #[arg(long, default_value_t = 1)]
    pub min_levels: usize,
    /// How the control points are solved for: `pia` (progressive iterative approximation),
    /// `lspia` (least-squares PIA), `cg` (conjugate gradients on the normal equations) or
    /// `direct` (sparse Cholesky, one step).
    #[arg(long, value_parser = named::<Method>(Method::ALL.map(Method::name)), default_value = "cg")]
    pub method: Method,
    /// Subdivided inputs: how the coarse net is recovered, `exact` (the inverse of the
    /// subdivision rules) or `lsq` (the net whose subdivision is closest in least squares).
    #[arg(long, value_parser = named::<InverseMethod>(InverseMethod::ALL.map(InverseMethod::name)), default_value = "exact")]
    pub inverse: InverseMethod,
    /// Maximum number of fitting steps.
    #[arg(long, default_value_t = BudgetConfig::default().max_iterations)]
    pub iterations: usize,
    /// Absolute tolerance; the default is 1e-3 of the bounding-box diagonal.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Tolerance as a fraction of the bounding-box diagonal (ignored with --tolerance).
    #[arg(long, default_value_t = BudgetConfig::default().tolerance_rel)]
    pub tolerance_rel: f64,
    /// Targets; with none given the fit aims at max error <= tolerance.
    #[arg(long)]
    pub max_error: Option<f64>,
    /// Target for the mean error (same unit as the input); the fit stops once every target
    /// given holds.
    #[arg(long)]
    pub mean_error: Option<f64>,
    /// Target share of data points within the tolerance, in percent (0-100).
    #[arg(long)]
    pub within_tolerance_pct: Option<f64>,
    /// Stop fitting after this many milliseconds (checked between steps); no limit by default.
    #[arg(long)]
    pub max_time_ms: Option<u64>,
    /// Scans without subdivision connectivity, `bezier`: control-net segments per side (the
    /// degree); `loop`: grid cells across the patch's longer side (default: chosen for
    /// --target-controls-pct).
    #[arg(long)]
    pub lattice: Option<usize>,
    /// Scans, `loop`, and whole objects: control points as a percentage of the data points.
    #[arg(long, default_value_t = ScanConfig::default().target_controls_pct)]
    pub target_controls_pct: f64,
    /// Scans: rounds of parameter correction (data parameters moved to foot points).
    #[arg(long, default_value_t = CorrectionConfig::default().rounds)]
    pub corrections: usize,
    /// Scans: what a correction round refits: `distance` (squared-distance minimisation)
    /// or `parameters` (point-to-point again).
    #[arg(long, value_parser = named::<Correction>(Correction::NAMES.iter().copied()), default_value = "distance")]
    pub correction: Correction,
    /// Scans: correction rounds stop once one lowers the geometric RMS by less than this
    /// fraction.
    #[arg(long, default_value_t = CorrectionConfig::default().min_gain)]
    pub correction_min_gain: f64,
    /// Scans, distance rounds: share of the point-to-point term beside point-to-plane
    /// inside the data (smaller: rounds converge faster and further)...
    #[arg(long, default_value_t = CorrectionConfig::default().tangential)]
    pub correction_tangential: f64,
    /// ... and within half a control spacing of the data's edges (smaller: the surface
    /// slides past the last points, higher maximum errors).
    #[arg(long, default_value_t = CorrectionConfig::default().tangential_edge)]
    pub correction_tangential_edge: f64,
    /// Whole objects: above 0, the rounds add the curvature's term of the squared distance
    /// (SDM) with this share where the surface is flat, in place of the tangential share
    /// (0: off; README, "Fitting").
    #[arg(long, default_value_t = CorrectionConfig::default().curvature_floor)]
    pub curvature_floor: f64,
    /// Scans: fairness weight relative to the data.
    #[arg(long, default_value_t = ScanConfig::default().smoothing)]
    pub smoothing: f64,
    /// Scans: fit the largest component (`largest`) or every component big enough (`all`,
    /// written to OUT/c0, OUT/c1, ... largest first, with OUT/components.json).
    #[arg(long, value_parser = named::<ComponentMode>(ComponentMode::NAMES.iter().copied()), default_value = "largest")]
    pub components: ComponentMode,
    /// Scans: components with fewer vertices are not fitted.
    #[arg(long, default_value_t = ComponentsConfig::default().min_vertices)]
    pub min_component_vertices: usize,
    /// Scans, `--components all`: components under this fraction of the largest (in
    /// vertices) are not fitted.
    #[arg(long, default_value_t = ComponentsConfig::default().min_fraction)]
    pub min_component_fraction: f64,
    /// Scans with `--surface bezier`: `patches` (one quartic Bezier patch per grid cell,
    /// the Bezier form of the grid fit) or `single` (one patch of degree `--lattice`, 16 by
    /// default; implied by `--lattice`).
    #[arg(long, value_parser = named::<BezierLayout>(BezierLayout::NAMES.iter().copied()), default_value = "patches")]
    pub bezier_layout: BezierLayout,
    /// Scans: holes whose bridging radius (largest distance from the hole's flat fill to
    /// its rim) exceeds this many median edge lengths of the data are trimmed out of the
    /// surface, narrower ones bridged; data triangles wider than that are trimmed too.
    #[arg(long, default_value_t = ScanConfig::default().hole_bridge_edges)]
    pub hole_bridge_edges: f64,
    /// Whole objects: a surface still straying past 0.5 % of the diagonal after its repair,
    /// where a decimation of as many vertices strays too, is fitted again at twice the
    /// controls it spent, at most this many times, and the least straying fit kept; then,
    /// where that still strays, faceted surfaces at twice the controls until one holds the
    /// bound (0: the budget holds).
    #[arg(long, default_value_t = ScanConfig::default().stray_budget_steps as u8, value_parser = clap::value_parser!(u8).range(0..=4))]
    pub stray_budget_steps: u8,
    /// `--surface dms`: the degree, 2 or 3 (C1 or C2 surfaces; 6 or 10 controls per domain
    /// triangle, their number set by --target-controls-pct).
    #[arg(long, default_value_t = DmsConfig::default().degree, value_parser = clap::value_parser!(u8).range(2..=3).map(usize::from))]
    pub dms_degree: usize,
    /// `--surface bpatch`: the degree (1-20).
    #[arg(long, default_value_t = BPatchConfig::default().degree, value_parser = clap::value_parser!(u8).range(1..=20).map(usize::from))]
    pub bpatch_degree: usize,
    /// `--surface dms`: knot cloud radius as a fraction of each domain vertex's shortest
    /// edge, in (0, 1); `bpatch`: knots pushed out along the medians by this fraction, in
    /// [0, 2] (0: the Bezier patch). Default: 0.6 for dms, 0.5 for bpatch.
    #[arg(long)]
    pub knot_spread: Option<f64>,
    /// Whole objects: data edges whose faces turn by more than this many degrees become
    /// sharp crease edges of the surface (0: none, nor the faceted surface).
    #[arg(long, default_value_t = DEFAULT_CREASE_ANGLE_DEG)]
    pub crease_angle_deg: f64,
    /// Whole objects: a shallower data edge (over 15 degrees) is a crease too where it turns
    /// this many times as much as the edges beside it, in a feature line of its own (0: off).
    #[arg(long, default_value_t = DEFAULT_CREASE_RELATIVE_RATIO)]
    pub crease_relative_ratio: f64,
    /// Whole objects with sharp edges, or whose smooth surface strays past the bound: also
    /// fit the faceted surface (every control edge a crease: the surface is the control
    /// mesh) and keep it where it is nearer the data; where no fit holds the stray bound,
    /// the faceted surface at more controls is the last resort.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub faceted: bool,
    /// Tessellation segments per side of the domain triangle in surface.glb.
    #[arg(long, default_value_t = DEFAULT_TESSELLATION)]
    pub tessellation: usize,
    /// Output folder (created if missing): surface.json, surface.glb and report.json (with
    /// --components all, in one subfolder per component).
    #[arg(long)]
    pub out: PathBuf,
}

impl FitArgs {
    /// The worker's configuration from the flags.
    fn worker_config(&self) -> WorkerConfig {
        let scan_defaults = ScanConfig::default();
        let fit = FitConfig {
            surface: self.surface,
            domain: self.domain,
            levels: self.levels,
            min_levels: self.min_levels,
            method: self.method,
            inverse: self.inverse,
            budget: BudgetConfig {
                max_iterations: self.iterations,
                tolerance: self.tolerance,
                tolerance_rel: self.tolerance_rel,
                max_error: self.max_error,
                mean_error: self.mean_error,
                within_tolerance_pct: self.within_tolerance_pct,
                max_time_ms: self.max_time_ms,
            },
            scan: ScanConfig {
                target_controls_pct: self.target_controls_pct,
                grid_segments: self.lattice.filter(|_| self.surface == SurfaceKind::Loop),
                // A degree given for `bezier` asks for one patch of that degree.
                bezier_layout: match (self.surface, self.lattice) {
                    (SurfaceKind::Bezier, Some(_)) => BezierLayout::Single,
                    _ => self.bezier_layout,
                },
                lattice: self.lattice.unwrap_or(scan_defaults.lattice),
                smoothing: self.smoothing,
                hole_bridge_edges: self.hole_bridge_edges,
                stray_budget_steps: usize::from(self.stray_budget_steps),
            },
            correction: CorrectionConfig {
                rounds: self.corrections,
                kind: self.correction,
                min_gain: self.correction_min_gain,
                tangential: self.correction_tangential,
                tangential_edge: self.correction_tangential_edge,
                curvature_floor: self.curvature_floor,
            },
            crease_angle_deg: self.crease_angle_deg,
            crease_relative_ratio: self.crease_relative_ratio,
            faceted: self.faceted,
            components: ComponentsConfig {
                mode: self.components,
                min_vertices: self.min_component_vertices,
                min_fraction: self.min_component_fraction,
            },
            // --knot-spread sets the spread of the kind asked for only: the two kinds'
            // ranges differ, and the config's check holds each kind to its own.
            dms: DmsConfig {
                degree: self.dms_degree,
                knot_spread: self
                    .knot_spread
                    .filter(|_| self.surface == SurfaceKind::Dms)
                    .unwrap_or(DmsConfig::default().knot_spread),
            },
            bpatch: BPatchConfig {
                degree: self.bpatch_degree,
                knot_spread: self
                    .knot_spread
                    .filter(|_| self.surface == SurfaceKind::Bpatch)
                    .unwrap_or(BPatchConfig::default().knot_spread),
            },
        };
        WorkerConfig {
            fit,
            tessellation: self.tessellation,
        }
    }
}

/// Runs `fit`: reads the mesh, fits it, writes the outputs.
pub fn run(args: &FitArgs) -> anyhow::Result<ExitCode> {
    let started = std::time::Instant::now();
    let cfg = args.worker_config();
    check_ranges(args)?;
    // The daemon's config refuses these values; the flags that set them do too. For
    // `loop`, --lattice is the grid's segments (`grid_segments`, checked as such), not a
    // Bezier degree.
    let mut checked = cfg.fit.clone();
    if checked.surface == SurfaceKind::Loop {
        checked.scan.lattice = ScanConfig::default().lattice;
    }
    if let Some((key, value, rule)) = crate::daemon::config::fit_out_of_range(&checked) {
        anyhow::bail!("out of range: {value} for {key} (the flag of that name): {rule}");
    }
    let mesh = read_mesh_file(&args.input, &LoadOptions::default())?.mesh;
    let read_ms = started.elapsed().as_secs_f64() * 1e3;
    let progress = Progress::new(cfg.fit.budget.max_iterations);
    let on_step = |s: &crate::fit::StepStats| progress.on_step(s);
    let fitted = run_input_with(&mesh, None, &cfg, Some(&on_step));
    progress.finish();
    let input = match fitted {
        Ok(o) => o,
        Err(e) if e.is_refusal() => {
            eprintln!("{}: cannot fit: {e}", args.input.display());
            return Ok(ExitCode::from(2));
        }
        Err(e) => return Err(e).context(format!("{}: fit failed", args.input.display())),
    };
    let label = args.input.display().to_string();
    let source = Source {
        label: &label,
        read_ms,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    if args.components == ComponentMode::Largest {
        for part in input.parts {
            println!(
                "{}",
                summary(&label, &part.outputs, &args.out, args.surface)
            );
            write_outputs(&args.out, part.outputs, &source)?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    let mut listing = Vec::new();
    for part in input.parts {
        let name = part.suffix.trim_start_matches('.').to_string();
        listing.push(json!({
            "component": name,
            "status": part.outputs.status,
            "data_points": part.outputs.report["data_points"],
            "final": part.outputs.report["final"],
        }));
        let dir = args.out.join(&name);
        println!(
            "{}",
            summary(
                &format!("{label} [{name}]"),
                &part.outputs,
                &dir,
                args.surface
            )
        );
        write_outputs(&dir, part.outputs, &source)?;
    }
    for (suffix, reason) in &input.failed {
        eprintln!("{label}: component {suffix} not fitted: {reason}");
    }
    let failed: Vec<_> = input
        .failed
        .iter()
        .map(|(s, r)| json!({"component": s.trim_start_matches('.'), "reason": r}))
        .collect();
    write_atomic(
        &args.out.join("components.json"),
        &serde_json::to_vec_pretty(&json!({"input": label, "fitted": listing, "failed": failed}))?,
    )?;
    Ok(ExitCode::SUCCESS)
}

/// Ranges said in the flags' own names: `--curvature-floor` within the config's range,
/// `--knot-spread` within the range of the kind asked for. Every other flag is held to the
/// config's ranges after it (`fit_out_of_range`), under the config's key.
fn check_ranges(args: &FitArgs) -> anyhow::Result<()> {
    let floor = args.curvature_floor;
    if !(0.0..1.0).contains(&floor) {
        anyhow::bail!("--curvature-floor {floor}: needs a value in [0, 1) (0: off)");
    }
    let Some(k) = args.knot_spread else {
        return Ok(());
    };
    match args.surface {
        SurfaceKind::Dms if !(k > 0.0 && k < 1.0) => {
            anyhow::bail!("--knot-spread {k}: dms needs a value in (0, 1)")
        }
        SurfaceKind::Bpatch if !(0.0..=2.0).contains(&k) => {
            anyhow::bail!("--knot-spread {k}: bpatch needs a value in [0, 2]")
        }
        _ => Ok(()),
    }
}

/// The line `fit` prints per fitted surface: how it ended (and what that means), its
/// errors, size and time, and what was left out. Errors are in the input's unit.
fn summary(label: &str, out: &PatchOutputs, dir: &Path, asked: SurfaceKind) -> String {
    let r = &out.report;
    let number = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let status = match out.status {
        FitStatus::Met => "met: every target holds".to_string(),
        FitStatus::Stalled => format!(
            "stalled: further steps stopped improving the fit before every target held \
            ({} see the README)",
            stall_reason(r)
        ),
        FitStatus::Capped => "capped: the step or time limit came first (raise --iterations or \
            --max-time-ms)"
            .to_string(),
    };
    let mut line = format!(
        "{label}: {status}; RMS {:.3e}, max {:.3e} (tolerance {:.3e}); {} control points for {} data points; fitted in {:.2} s; -> {}",
        number(&r["final"]["geometric_rms_error"]),
        number(&r["final"]["geometric_max_error"]),
        number(&r["tolerance"]),
        r["control_points"],
        r["data_points"],
        number(&r["wall_ms"]) / 1e3,
        dir.display(),
    );
    let dropped = &r["dropped"];
    if let Some(pieces) = dropped["pieces"].as_u64().filter(|&p| p > 0) {
        line.push_str(&format!(
            "; {pieces} {} not fitted ({} vertices, {:.1} %; --components all fits every sizeable piece)",
            if pieces == 1 { "piece" } else { "pieces" },
            dropped["vertices"],
            100.0 * number(&dropped["share"]),
        ));
    }
    if let Some(said) = other_kind_clause(r, asked) {
        line.push_str(&said);
    }
    if let Some(said) = escalation_summary(&r["object"], &r["control_points"]) {
        line.push_str(&said);
        if r["control_points"] == r["data_points"] && r["object"]["faceted"]["kept_faceted"] == true
        {
            line.push_str(
                "; no fewer controls held the bound: the surface is the cleaned input mesh itself",
            );
        }
    }
    if let Some(said) = faceted_clause(&r["object"]["faceted"]) {
        line.push_str(&said);
    }
    if let Some(added) = stray_repair_controls(&r["object"]["refinement"]) {
        line.push_str(&format!(
            "; {added} control points added where the surface strayed from the data (the \
            stray repair, over the target)"
        ));
    }
    if let Some(said) = stray_clause(r) {
        line.push_str(&said);
    }
    line
}

/// What the line says when the surface written is not the kind asked for: a whole object
/// (closed, holed, with handles) is fitted as a Loop surface whatever kind was asked, and
/// report.json's `surface` says so; `None` when it is the kind asked for.
fn other_kind_clause(report: &serde_json::Value, asked: SurfaceKind) -> Option<String> {
    let written = report["surface"].as_str()?;
    (written != asked.name()).then(|| {
        format!(
            "; written as a {written} surface, not {}: the {} path fits Loop surfaces only \
            (--surface {} takes disk-like scans and inputs with subdivision connectivity)",
            asked.name(),
            report["path"].as_str().unwrap_or("fit's"),
            asked.name()
        )
    })
}

/// Why a fit of the path report.json names usually stalls, and its remedy: a whole
/// object's max error is held up by its control budget as much as by the data's noise, an
/// exact-subdivision fit's by its coarse net (refined down to `--min-levels` already), a
/// scan's by its noise and rims.
fn stall_reason(report: &serde_json::Value) -> &'static str {
    match report["path"].as_str() {
        Some("object") => {
            "usual for whole objects: detail finer than the control budget can follow, and \
            scan noise, keep the max error above the tolerance; judge it by the RMS, or raise \
            --target-controls-pct;"
        }
        Some("subdivided") => {
            "usual for inputs with subdivision connectivity whose detail or noise is finer \
            than the coarsest net tried (--min-levels); judge it by the RMS, or lower \
            --min-levels;"
        }
        _ => {
            "usual for scans, whose noise and rims keep the max error above the tolerance; \
            judge it by the RMS,"
        }
    }
}

/// What the line says of a surface straying past the bound (report.json `stray`, which
/// every path that measures it writes), with the remedy of its path; `None` within it or
/// unmeasured.
fn stray_clause(report: &serde_json::Value) -> Option<String> {
    let stray = &report["stray"];
    if stray["within"].as_bool() != Some(false) {
        return None;
    }
    let hint = if report["object"].is_null() {
        "the surface of this path is kept as it is; --domain mesh fits the input as a whole \
        object, whose surface is repaired towards the bound"
    } else {
        "over a hole or a coarse mesh's large triangles; a higher --target-controls-pct \
        brings it closer"
    };
    let share = |key: &str| 100.0 * stray[key].as_f64().unwrap_or(f64::NAN);
    Some(format!(
        "; the surface strays up to {:.2} % of the bounding-box diagonal from the data (over \
        {:.2} %: {hint})",
        share("share_of_diagonal"),
        share("limit_share"),
    ))
}

/// What the line says of a stray escalation (`object.stray_budgets`, more than one fit
/// tried): the controls of the first fit, the budgets tried after it, and which surface
/// was kept; `None` without one.
fn escalation_summary(object: &serde_json::Value, controls: &serde_json::Value) -> Option<String> {
    let budgets = object["stray_budgets"].as_array().filter(|b| b.len() > 1)?;
    // The last resort's faceted surfaces (fitted, then as decimated, at one count) are
    // named once per count.
    let mut again: Vec<String> = budgets[1..]
        .iter()
        .map(|b| match b["faceted"].as_bool() {
            Some(true) => format!("{} faceted", b["target"]),
            _ => b["target"].to_string(),
        })
        .collect();
    again.dedup();
    let outcome = if object["stray"]["within"].as_bool() == Some(true) {
        format!("the surface of {controls} kept")
    } else if budgets[0]["kept"].as_bool() == Some(true) {
        "none strayed less, the first is kept".to_string()
    } else {
        format!(
            "none came within the bound; the surface of {controls}, which strays least, is kept"
        )
    };
    Some(format!(
        "; the fit at {} control points strayed from the data, so it was fitted again at {} \
         ({outcome}; report.json object.stray_budgets)",
        budgets[0]["controls"],
        again.join(" and "),
    ))
}

/// What the line says when the faceted surface was kept (`object.faceted`): a user who
/// asked for a smooth surface should hear that this one has sharp edges everywhere.
fn faceted_clause(faceted: &serde_json::Value) -> Option<String> {
    if faceted["kept_faceted"].as_bool() != Some(true) {
        return None;
    }
    let rms = |key: &str| faceted[key].as_f64().unwrap_or(f64::NAN);
    Some(format!(
        "; faceted: every control edge is a crease, so the surface is its control mesh, \
         {:.3e} RMS from the data against the smooth surface's {:.3e} (report.json \
         object.faceted; --faceted false keeps the smooth one)",
        rms("faceted_rms"),
        rms("smooth_rms"),
    ))
}

/// Control points the stray repair's rounds added (report.json `object.refinement`), when
/// any round it took was kept.
fn stray_repair_controls(refinement: &serde_json::Value) -> Option<u64> {
    let rounds = refinement.as_array()?;
    let repaired = |r: &&serde_json::Value| r["stray_repair"].as_bool() == Some(true);
    let before = rounds.iter().rev().find(|r| !repaired(r))?["controls"].as_u64()?;
    let after = rounds.last().filter(repaired)?["controls"].as_u64()?;
    (after > before).then(|| after - before)
}

/// Where a fit's mesh came from, for its report.
struct Source<'a> {
    label: &'a str,
    /// Reading and parsing the input file (the report's `wall_ms` starts after it).
    read_ms: f64,
}

/// One surface's files; surface.json last, its presence marks a complete set.
fn write_outputs(dir: &Path, mut out: PatchOutputs, source: &Source) -> anyhow::Result<()> {
    out.report["input"] = json!(source.label);
    out.report["read_ms"] = json!(source.read_ms);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let report = serde_json::to_vec_pretty(&out.report)?;
    let surface = serde_json::to_vec_pretty(&out.surface)?;
    // As the daemon writes them: all synced at once, surface.json renamed last.
    write_atomic_group(
        dir,
        &[
            ("surface.glb", &out.glb),
            ("legend.svg", out.legend.as_bytes()),
            ("report.json", &report),
            ("surface.json", &surface),
        ],
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{escalation_summary, other_kind_clause, stall_reason, stray_clause};
    use crate::pipeline::SurfaceKind;
    use serde_json::json;

    #[test]
    fn a_surface_of_another_kind_than_asked_is_said() {
        let report = json!({"surface": "loop", "path": "object"});
        let said = other_kind_clause(&report, SurfaceKind::Bezier).unwrap_or_default();
        assert!(
            said.contains("written as a loop surface, not bezier"),
            "{said}"
        );
        assert!(said.contains("object path"), "{said}");
        assert_eq!(other_kind_clause(&report, SurfaceKind::Loop), None);
    }

    #[test]
    fn a_stall_is_explained_with_its_own_path_s_remedy() {
        let of = |path: &str| stall_reason(&json!({ "path": path }));
        assert!(of("object").contains("--target-controls-pct"));
        assert!(of("subdivided").contains("lower --min-levels"));
        for scan in ["scan", "planar"] {
            assert!(of(scan).starts_with("usual for scans"), "{scan}");
        }
        let all = ["object", "subdivided", "scan"].map(of);
        assert!(all[0] != all[1] && all[1] != all[2] && all[0] != all[2]);
    }

    fn object(within: bool, kept: usize) -> serde_json::Value {
        let budgets: Vec<_> = [(22, 28), (56, 62), (124, 124)]
            .iter()
            .enumerate()
            .map(|(k, &(target, controls))| {
                json!({"target": target, "controls": controls, "kept": k == kept})
            })
            .collect();
        json!({"stray_budgets": budgets, "stray": {"within": within}})
    }

    #[test]
    fn the_line_names_the_fit_an_escalation_kept() {
        let said = |within, kept, controls| {
            escalation_summary(&object(within, kept), &json!(controls)).unwrap_or_default()
        };
        let tried = "the fit at 28 control points strayed from the data, so it was fitted \
                     again at 56 and 124";
        assert!(said(true, 2, 124).contains(tried));
        assert!(said(true, 2, 124).contains("(the surface of 124 kept;"));
        assert!(said(false, 0, 28).contains("(none strayed less, the first is kept;"));
        assert!(said(false, 1, 62).contains(
            "(none came within the bound; the surface of 62, which strays least, is kept;"
        ));
        let mut last_resort = object(true, 2);
        last_resort["stray_budgets"][2]["faceted"] = json!(true);
        let faceted = json!({"target": 124, "controls": 124, "faceted": true, "kept": false});
        if let Some(b) = last_resort["stray_budgets"].as_array_mut() {
            b.insert(2, faceted);
        }
        let said = escalation_summary(&last_resort, &json!(124)).unwrap_or_default();
        assert!(
            said.contains("fitted again at 56 and 124 faceted ("),
            "{said}"
        );
        let one = json!({"stray_budgets": [{"target": 22, "controls": 28, "kept": true}]});
        assert_eq!(escalation_summary(&one, &json!(28)), None);
        assert_eq!(escalation_summary(&json!({}), &json!(28)), None);
    }

    #[test]
    fn the_line_says_a_stray_past_the_bound_with_its_paths_remedy() {
        let stray =
            |within| json!({"within": within, "share_of_diagonal": 0.0068, "limit_share": 0.005});
        let exact = json!({"stray": stray(false)});
        let said = stray_clause(&exact).unwrap_or_default();
        assert!(said.contains("strays up to 0.68 %"), "{said}");
        assert!(said.contains("--domain mesh"), "{said}");
        let object = json!({"stray": stray(false), "object": {"stray": stray(false)}});
        let said = stray_clause(&object).unwrap_or_default();
        assert!(said.contains("--target-controls-pct"), "{said}");
        assert_eq!(stray_clause(&json!({"stray": stray(true)})), None);
        assert_eq!(stray_clause(&json!({})), None);
    }
}
