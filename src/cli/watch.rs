//! `trispline watch`: the daemon's command line.

use crate::daemon::config::{DaemonConfig, LogFormat, DEFAULT_CONFIG};
use crate::daemon::pipe::PipeSpec;
use crate::daemon::{run, Control, DaemonOptions};
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

/// Arguments of `trispline watch`.
#[derive(clap::Args, Debug)]
pub struct WatchArgs {
    /// Folder to watch for mesh files.
    pub dir: PathBuf,
    /// Output folder (created if missing): OUT/<id> holds each patch's latest outputs,
    /// beside the event log (events.ndjson) and, unless the config moves it, quarantine/.
    #[arg(long)]
    pub out: PathBuf,
    /// Also read records from this FIFO, or `-` for stdin (stdin EOF ends the daemon once
    /// the work is done).
    #[arg(long)]
    pub pipe: Option<PathBuf>,
    /// Warm-start state (default OUT/.state).
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// TOML config; without it the embedded default is used. Re-read on SIGHUP and when
    /// the file changes.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Process what is there, then exit.
    #[arg(long)]
    pub once: bool,
    /// Print the effective configuration (the file's or the embedded one) as TOML and exit.
    #[arg(long)]
    pub print_config: bool,
    /// Check the configuration and exit (0: valid).
    #[arg(long)]
    pub check_config: bool,
    /// Log lines as JSON (overrides log.format).
    #[arg(long)]
    pub log_json: bool,
    /// Files in subfolders are patches too: DIR/scans/ear.ply is patch `scans/ear`, with
    /// outputs in OUT/scans/ear/ (sets daemon.recursive).
    #[arg(long)]
    pub recursive: bool,
    /// Publish the jobs to this NATS JetStream server (`nats://HOST:PORT`, sets cluster.url)
    /// for `trispline worker` processes to fit, instead of fitting them here. OUT must be
    /// the workers' shared OUT.
    #[arg(long)]
    pub queue: Option<String>,
}

/// The daemon configuration from `path`, or the embedded default without one. An invalid
/// configuration is printed and becomes exit code 2; an unreadable file is an error.
pub(crate) fn load_config(path: Option<&Path>) -> anyhow::Result<Result<DaemonConfig, ExitCode>> {
    let text = match path {
        Some(p) => {
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?
        }
        None => DEFAULT_CONFIG.to_string(),
    };
    Ok(DaemonConfig::parse(&text, &config_name(path)).map_err(|e| {
        eprintln!("{e}");
        ExitCode::from(2)
    }))
}

/// How messages name the configuration's source.
fn config_name(path: Option<&Path>) -> String {
    path.map_or_else(
        || "embedded config/default.toml".to_string(),
        |p| p.display().to_string(),
    )
}

/// Runs `watch`: loads the configuration, then the daemon until it is stopped (or, with
/// --once, until the folder's files are processed).
pub fn run_watch(args: &WatchArgs) -> anyhow::Result<ExitCode> {
    let config = match load_config(args.config.as_deref())? {
        Ok(mut c) => {
            c.daemon.recursive |= args.recursive;
            if args.queue.is_some() {
                c.cluster.url.clone_from(&args.queue);
            }
            c
        }
        Err(code) => return Ok(code),
    };
    if config.object.folders && config.cluster.url.is_some() {
        // Each object's fit reads its whole folder, which a queue's workers do not see.
        anyhow::bail!("object.folders cannot be used with a queue (cluster.url, --queue)");
    }
    if args.print_config {
        print!("{}", config.to_toml());
        return Ok(ExitCode::SUCCESS);
    }
    if args.check_config {
        println!("{}: ok", config_name(args.config.as_deref()));
        return Ok(ExitCode::SUCCESS);
    }
    let set_log_level = init_logging(&config, args.log_json);
    let ctl = Control {
        set_log_level: Some(set_log_level),
        ..Control::default()
    };
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&ctl.stop))
            .context("installing signal handlers")?;
    }
    signal_hook::flag::register(signal_hook::consts::SIGHUP, Arc::clone(&ctl.reload))
        .context("installing the SIGHUP handler")?;
    let pipe = args.pipe.as_ref().map(|p| {
        if p.as_os_str() == "-" {
            PipeSpec::Stdin
        } else {
            PipeSpec::Fifo(p.clone())
        }
    });
    let offload = match &config.cluster.url {
        Some(url) => Some(
            crate::cluster::offload(url, &config, &args.out)
                .with_context(|| format!("queue {url}"))?,
        ),
        None => None,
    };
    let opts = DaemonOptions {
        watch_dir: args.dir.clone(),
        out_dir: args.out.clone(),
        state_dir: args
            .state
            .clone()
            .unwrap_or_else(|| args.out.join(".state")),
        once: args.once,
        config,
        config_path: args.config.clone(),
        pipe,
        offload,
    };
    let summary = run(opts, &ctl)?;
    eprintln!(
        "fitted {}, rejected {}, superseded {}, unchanged {}",
        summary.fitted, summary.rejected, summary.superseded, summary.unchanged
    );
    Ok(ExitCode::SUCCESS)
}

pub(crate) type SetLevel = Box<dyn Fn(&str) -> Result<(), String> + Send + Sync>;

/// Logs to stderr, human or JSON, with a filter that a config reload can replace. RUST_LOG,
/// when set, wins at start-up; a reload applies `log.level`.
pub(crate) fn init_logging(config: &DaemonConfig, force_json: bool) -> SetLevel {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    use tracing_subscriber::{fmt, reload, EnvFilter};
    let filter = EnvFilter::try_from_default_env()
        .or_else(|_| EnvFilter::try_new(&config.log.level))
        .unwrap_or_else(|_| EnvFilter::new("info"));
    let (filter, handle) = reload::Layer::new(filter);
    let registry = tracing_subscriber::registry().with(filter);
    let _ = if force_json || config.log.format == LogFormat::Json {
        registry
            .with(fmt::layer().json().with_writer(std::io::stderr))
            .try_init()
    } else {
        registry
            .with(
                fmt::layer()
                    .with_writer(std::io::stderr)
                    .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr())),
            )
            .try_init()
    };
    Box::new(move |level: &str| {
        let f = EnvFilter::try_new(level).map_err(|e| e.to_string())?;
        handle.reload(f).map_err(|e| e.to_string())
    })
}
