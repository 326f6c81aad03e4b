//! Unit tests of the daemon configuration: parsing, merging over the defaults, validation.

use super::*;
use crate::pipeline::worker::BudgetConfig;

#[test]
fn embedded_default_parses_and_round_trips() {
    let cfg = DaemonConfig::embedded_default().expect("valid default");
    let again = DaemonConfig::parse(&cfg.to_toml(), "printed").expect("printed config parses");
    assert_eq!(again.to_toml(), cfg.to_toml());
    assert_eq!(again.fit_hash(), cfg.fit_hash());
}

#[test]
fn unknown_key_is_named_with_line_and_column() {
    let text = DEFAULT_CONFIG.replace("lattice = 16", "latice = 16");
    let e = DaemonConfig::parse(&text, "my.toml")
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("my.toml") && e.contains("latice") && e.contains("line"),
        "{e}"
    );
}

#[test]
fn out_of_range_value_is_refused() {
    let text = DEFAULT_CONFIG.replace("levels = 2", "levels = 9");
    let e = DaemonConfig::parse(&text, "my.toml")
        .expect_err("refused")
        .to_string();
    assert!(e.contains("fit.levels"), "{e}");
}

#[test]
fn metrics_address_must_be_loopback() {
    let with = |addr: &str| {
        DEFAULT_CONFIG.replace(
            "# metrics_addr = \"127.0.0.1:9187\"",
            &format!("metrics_addr = \"{addr}\""),
        )
    };
    assert!(DaemonConfig::parse(&with("127.0.0.1:9187"), "m.toml").is_ok());
    assert!(DaemonConfig::parse(&with("[::1]:9187"), "m.toml").is_ok());
    let e = DaemonConfig::parse(&with("0.0.0.0:9187"), "m.toml")
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("daemon.metrics_addr") && e.contains("loopback"),
        "{e}"
    );
    assert!(DaemonConfig::parse(&with("localhost"), "m.toml").is_err());
}

#[test]
fn new_keys_have_defaults_and_are_checked() {
    let old = "[fit]\nsurface = \"bezier\"\nlevels = 1\nmethod = \"cg\"\ninverse = \"exact\"\n[daemon]\nsettle_ms = 0\npoll_interval_ms = 50\nmax_file_bytes = 100\nmax_vertices = 100\n";
    let cfg = DaemonConfig::parse(old, "old.toml").expect("configs without the new keys");
    assert_eq!(cfg.fit.budget, BudgetConfig::default());
    assert_eq!(cfg.fit.scan, ScanConfig::default());
    assert_eq!(cfg.output.tessellation, DEFAULT_TESSELLATION);
    assert_eq!(cfg.daemon.watcher, WatcherKind::Native);
    assert_eq!(cfg.output.processed, ProcessedPolicy::Leave);
    assert!(cfg.output.glb && cfg.output.report);
    let e = DaemonConfig::parse(&format!("{old}watcher = \"smoke\"\n"), "w.toml")
        .expect_err("refused")
        .to_string();
    assert!(e.contains("watcher"), "{e}");
    let e = DaemonConfig::parse(&format!("{old}[log]\nlevel = \"=[\"\n"), "l.toml")
        .expect_err("refused")
        .to_string();
    assert!(e.contains("log.level"), "{e}");
}

#[test]
fn fit_hash_follows_the_fit_section_only() {
    let a = DaemonConfig::embedded_default().expect("default");
    let mut b = a.clone();
    b.daemon.settle_ms += 1;
    b.output.tessellation += 1;
    b.output.glb = false;
    b.log.level = "debug".into();
    assert_eq!(a.fit_hash(), b.fit_hash());
    assert_eq!(b.wanted_outputs(), ["surface.json", "report.json"]);
    b.fit.budget.max_iterations += 1;
    assert_ne!(a.fit_hash(), b.fit_hash());
    assert_ne!(a.object_fit_hash(), b.object_fit_hash());
}

#[test]
fn the_object_table_refits_objects_only_whether_folders_are_on_or_not() {
    let a = DaemonConfig::embedded_default().expect("default");
    assert!(!a.object.folders);
    let mut b = a.clone();
    // Pipe objects exist with folders off: their merge must still count.
    b.object.merge.cell_edges *= 2.0;
    assert_eq!(a.fit_hash(), b.fit_hash());
    assert_ne!(a.object_fit_hash(), b.object_fit_hash());
    assert_eq!(b.state_fit(true).0, b.object_fit_hash());
    assert_eq!(b.state_fit(false).0, b.fit_hash());
    // Turning folders on refits objects, and no patch.
    let mut c = a.clone();
    c.object.folders = true;
    assert_eq!(a.fit_hash(), c.fit_hash());
    assert_ne!(a.object_fit_hash(), c.object_fit_hash());
}

#[test]
fn a_partial_file_is_merged_over_the_defaults() {
    let text = "[fit.budget]\nmax_iterations = 7\n";
    let cfg = DaemonConfig::parse(text, "partial.toml").expect("partial config");
    let default = DaemonConfig::embedded_default().expect("default");
    assert_eq!(cfg.fit.budget.max_iterations, 7);
    assert_eq!(cfg.daemon.settle_ms, default.daemon.settle_ms);
    assert_eq!(cfg.fit.scan.lattice, default.fit.scan.lattice);
    // Unknown keys are still refused, named, in partial files too.
    for (bad, key) in [
        ("[fit.budget]\nmax_iteration = 7\n", "max_iteration"),
        (
            "[fit.budget]\nmax_iterations = 7\n[daemon]\nsetle_ms = 1\n",
            "setle_ms",
        ),
        ("[daemon]\nsettle_ms = 1\n[fit]\nlevel = 1\n", "level"),
    ] {
        let e = DaemonConfig::parse(bad, "partial.toml").expect_err("refused");
        assert!(e.to_string().contains(key), "{bad}: {e}");
    }
    // Ranges hold after the merge.
    let e = DaemonConfig::parse("[fit]\nlevels = 9\n", "p.toml").expect_err("range");
    assert!(e.to_string().contains("fit.levels"), "{e}");
}

#[test]
fn keys_of_the_flat_fit_table_are_refused_with_their_name() {
    let flat = "[fit]\nsurface = \"loop\"\nlevels = 2\nmethod = \"cg\"\ninverse = \"exact\"\nmax_iterations = 5\n[daemon]\nsettle_ms = 0\npoll_interval_ms = 50\nmax_file_bytes = 100\nmax_vertices = 100\n";
    let e = DaemonConfig::parse(flat, "flat.toml").expect_err("refused");
    assert_eq!(e.kind(), "config_parse");
    assert!(e.to_string().contains("max_iterations"), "{e}");
}

#[test]
fn sub_table_ranges_are_named_by_their_whole_key() {
    let text = DEFAULT_CONFIG.replace("rounds = 8", "rounds = 101");
    let e = DaemonConfig::parse(&text, "r.toml").expect_err("refused");
    assert_eq!(e.kind(), "config_out_of_range");
    assert!(e.to_string().contains("fit.correction.rounds"), "{e}");
    let text = DEFAULT_CONFIG.replace("tessellation = 128", "tessellation = 0");
    let e = DaemonConfig::parse(&text, "t.toml").expect_err("refused");
    assert!(e.to_string().contains("output.tessellation"), "{e}");
}

#[test]
fn crease_relative_ratio_is_off_or_above_one() {
    let with = |ratio: &str| {
        DEFAULT_CONFIG.replace(
            "crease_relative_ratio = 6.0",
            &format!("crease_relative_ratio = {ratio}"),
        )
    };
    assert_eq!(
        DaemonConfig::parse(&with("0.0"), "c.toml")
            .expect("off")
            .fit
            .crease_relative_ratio,
        0.0
    );
    assert!(DaemonConfig::parse(&with("3.5"), "c.toml").is_ok());
    let e = DaemonConfig::parse(&with("0.5"), "c.toml")
        .expect_err("refused")
        .to_string();
    assert!(e.contains("fit.crease_relative_ratio"), "{e}");
}

#[test]
fn curvature_floor_is_off_by_default_and_checked() {
    let with = |floor: &str| {
        DEFAULT_CONFIG.replace(
            "curvature_floor = 0.0",
            &format!("curvature_floor = {floor}"),
        )
    };
    let cfg = DaemonConfig::embedded_default().expect("default");
    assert_eq!(cfg.fit.correction.curvature_floor(), None);
    let on = DaemonConfig::parse(&with("3e-4"), "on.toml").expect("a floor");
    assert_eq!(on.fit.correction.curvature_floor(), Some(3e-4));
    for bad in ["-0.1", "1.0"] {
        let e = DaemonConfig::parse(&with(bad), "bad.toml").expect_err("refused");
        assert_eq!(e.kind(), "config_out_of_range");
        assert!(
            e.to_string().contains("fit.correction.curvature_floor"),
            "{e}"
        );
    }
}
