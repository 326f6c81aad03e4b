//! `trispline watch`: the daemon's command line.

use crate::daemon::config::{DaemonConfig, DEFAULT_CONFIG};
use crate::daemon::{run, DaemonOptions};
use anyhow::Context;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

#[derive(clap::Args, Debug)]
pub struct WatchArgs {
    /// Folder to watch for mesh files.
    pub dir: PathBuf,
    #[arg(long)]
    pub out: PathBuf,
    /// Warm-start state (default OUT/.state).
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// TOML config; without it the embedded default is used.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Process what is there, then exit.
    #[arg(long)]
    pub once: bool,
    #[arg(long)]
    pub print_config: bool,
    #[arg(long)]
    pub check_config: bool,
    /// Log lines as JSON.
    #[arg(long)]
    pub log_json: bool,
}

pub fn run_watch(args: &WatchArgs) -> anyhow::Result<ExitCode> {
    let (text, name) = match &args.config {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?,
            p.display().to_string(),
        ),
        None => (
            DEFAULT_CONFIG.to_string(),
            "embedded config/default.toml".to_string(),
        ),
    };
    let config = match DaemonConfig::parse(&text, &name) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            return Ok(ExitCode::from(2));
        }
    };
    if args.print_config {
        print!("{}", config.to_toml());
        return Ok(ExitCode::SUCCESS);
    }
    if args.check_config {
        println!("{name}: ok");
        return Ok(ExitCode::SUCCESS);
    }
    let builder = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        );
    let _ = if args.log_json {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop))
            .context("installing signal handlers")?;
    }
    let opts = DaemonOptions {
        watch_dir: args.dir.clone(),
        out_dir: args.out.clone(),
        state_dir: args
            .state
            .clone()
            .unwrap_or_else(|| args.out.join(".state")),
        once: args.once,
        config,
    };
    let summary = run(&opts, &stop)?;
    eprintln!(
        "fitted {}, rejected {}, superseded {}, unchanged {}",
        summary.fitted, summary.rejected, summary.superseded, summary.unchanged
    );
    Ok(ExitCode::SUCCESS)
}
