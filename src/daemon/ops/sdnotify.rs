//! systemd notifications through the `sd-notify` crate (no libsystemd): readiness, reload and
//! stop, and the watchdog keep-alive when the unit sets `WatchdogSec=`.

use sd_notify::NotifyState;
use std::time::{Duration, Instant};

/// A state change the daemon reports.
#[derive(Clone, Copy, Debug)]
pub enum State {
    /// The watch is in place (and again after a reload).
    Ready,
    /// A config reload starts.
    Reloading,
    /// A graceful stop starts.
    Stopping,
}

/// Sends `state` when run under systemd with `Type=notify`; does nothing otherwise.
/// Failures are logged, never fatal: the daemon works the same without a supervisor.
pub fn notify(state: State) {
    let s = match state {
        State::Ready => NotifyState::Ready,
        State::Reloading => NotifyState::Reloading,
        State::Stopping => NotifyState::Stopping,
    };
    send(&[s]);
}

fn send(states: &[NotifyState]) {
    let Some(target) = std::env::var_os("NOTIFY_SOCKET") else {
        return;
    };
    let sent = match abstract_name(&target) {
        Some(name) => send_abstract(name, states),
        None => sd_notify::notify(false, states),
    };
    if let Err(e) = sent {
        tracing::warn!(error = %e, socket = ?target, "cannot notify systemd");
    }
}

/// The name of an abstract socket (`@name`), which systemd hands out in some containers.
/// sd-notify 0.4 connects to `NOTIFY_SOCKET` as a path, so these few lines stay ours.
fn abstract_name(target: &std::ffi::OsStr) -> Option<&[u8]> {
    use std::os::unix::ffi::OsStrExt;
    target.as_bytes().strip_prefix(b"@")
}

/// The same datagram sd-notify sends (one `STATE=value` line per state), to an abstract
/// socket.
fn send_abstract(name: &[u8], states: &[NotifyState]) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::os::linux::net::SocketAddrExt;
        let text: String = states.iter().map(|s| format!("{s}\n")).collect();
        let addr = std::os::unix::net::SocketAddr::from_abstract_name(name)?;
        std::os::unix::net::UnixDatagram::unbound()?.send_to_addr(text.as_bytes(), &addr)?;
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (name, states);
        Err(std::io::Error::other("abstract sockets need Linux"))
    }
}

/// The watchdog keep-alive: `WATCHDOG=1` at half the interval systemd asks for
/// (`WATCHDOG_USEC`), sent from the scheduler loop so that a loop that hangs stops the
/// keep-alives and systemd restarts the service.
pub struct Watchdog {
    every: Option<Duration>,
    last: Option<Instant>,
}

impl Watchdog {
    /// Reads `WATCHDOG_USEC` (and `WATCHDOG_PID`, which must be this process).
    pub fn from_env() -> Self {
        let mut usec = 0u64;
        let every = (sd_notify::watchdog_enabled(false, &mut usec) && usec > 0)
            .then(|| Duration::from_micros(usec / 2));
        if let Some(e) = every {
            tracing::info!(every_ms = e.as_millis() as u64, "systemd watchdog on");
        }
        Self { every, last: None }
    }

    /// Sends a keep-alive if one is due.
    pub fn tick(&mut self) {
        let Some(every) = self.every else { return };
        if self.last.is_some_and(|t| t.elapsed() < every) {
            return;
        }
        send(&[NotifyState::Watchdog]);
        self.last = Some(Instant::now());
    }
}
