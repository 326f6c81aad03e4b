//! `trispline worker`: fits jobs from a NATS JetStream work queue into a shared OUT.

use crate::cluster::{run_worker, WorkerOptions};
use crate::daemon::Control;
use anyhow::Context;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

/// Arguments of `trispline worker`.
#[derive(clap::Args, Debug)]
pub struct WorkerArgs {
    /// The NATS JetStream server (`nats://HOST:PORT`); default: cluster.url of the config.
    #[arg(long)]
    pub queue: Option<String>,
    /// The shared output folder (the same OUT as `watch --queue`'s).
    #[arg(long)]
    pub out: PathBuf,
    /// TOML config (the same `[fit]` as the sources', for identical results); without it
    /// the embedded default.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// This worker's name in events and claims (default: host name and process id).
    #[arg(long)]
    pub name: Option<String>,
    /// Serve /metrics and /healthz here (loopback; overrides daemon.metrics_addr).
    #[arg(long)]
    pub metrics_addr: Option<String>,
    /// Log lines as JSON (overrides log.format).
    #[arg(long)]
    pub log_json: bool,
}

/// Runs a worker until SIGTERM/SIGINT (the fit in progress finishes first).
pub fn run(args: &WorkerArgs) -> anyhow::Result<ExitCode> {
    let mut config = match super::watch::load_config(args.config.as_deref())? {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    if args.metrics_addr.is_some() {
        config.daemon.metrics_addr.clone_from(&args.metrics_addr);
    }
    let Some(url) = args.queue.clone().or_else(|| config.cluster.url.clone()) else {
        eprintln!("worker: no queue (--queue nats://HOST:PORT or cluster.url)");
        return Ok(ExitCode::from(2));
    };
    let _ = super::watch::init_logging(&config, args.log_json);
    let ctl = Control::default();
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&ctl.stop))
            .context("installing signal handlers")?;
    }
    let name = args.name.clone().unwrap_or_else(|| {
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
        format!("{}-{}", host.trim(), std::process::id())
    });
    let opts = WorkerOptions {
        url,
        out_dir: args.out.clone(),
        config,
        name,
    };
    let summary = run_worker(opts, &ctl).context("worker")?;
    eprintln!(
        "fitted {}, rejected {}, superseded {}, unchanged {}",
        summary.fitted, summary.rejected, summary.superseded, summary.unchanged
    );
    Ok(ExitCode::SUCCESS)
}
