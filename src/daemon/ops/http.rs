//! A minimal HTTP/1.1 responder for `/metrics` and `/healthz`: one request per connection,
//! answered and closed, each connection on a thread of its own (at most `MAX_CONNECTIONS`
//! at once) so that a slow client cannot hold `/healthz` from a supervisor. Loopback only
//! (checked in config validation), no authentication.
//!
//! Kept rather than `tiny_http`: what this endpoint must guarantee is a bound on a slow or
//! silent client (issue 22), and tiny_http's is a per-read timeout that every trickled byte
//! resets (tiny-http PR #20), with no deadline for the whole request and no cap on
//! connections or the threads serving them; two GET routes need nothing else it offers.
//! The exposition format itself comes from `prometheus-client` (`metrics.rs`).

use super::metrics::Metrics;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Connections served at once; more are closed at once (a client retries).
const MAX_CONNECTIONS: usize = 32;
/// The whole request must arrive within this, however slowly it trickles in.
const REQUEST_DEADLINE: Duration = Duration::from_secs(2);

/// Counts a connection's thread while it lives.
struct Slot(Arc<AtomicUsize>);

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Binds now (so that a taken port fails the start-up, not some later moment) and serves
/// on a thread of its own.
pub(crate) fn serve(addr: &str, metrics: Arc<Metrics>) -> std::io::Result<std::net::SocketAddr> {
    let listener = TcpListener::bind(addr)?;
    let local = listener.local_addr()?;
    let open = Arc::new(AtomicUsize::new(0));
    std::thread::Builder::new()
        .name("metrics".into())
        .spawn(move || {
            for conn in listener.incoming() {
                let stream = match conn {
                    Ok(s) => s,
                    Err(e) => {
                        tracing::debug!(error = %e, "metrics accept");
                        continue;
                    }
                };
                if open.fetch_add(1, Ordering::Relaxed) >= MAX_CONNECTIONS {
                    open.fetch_sub(1, Ordering::Relaxed);
                    continue;
                }
                let slot = Slot(Arc::clone(&open));
                let metrics = Arc::clone(&metrics);
                let spawned = std::thread::Builder::new()
                    .name("metrics-conn".into())
                    .spawn(move || {
                        let _slot = slot;
                        if let Err(e) = answer(stream, &metrics) {
                            tracing::debug!(error = %e, "metrics connection");
                        }
                    });
                if let Err(e) = spawned {
                    tracing::warn!(error = %e, "cannot serve a metrics connection");
                }
            }
        })?;
    Ok(local)
}

fn answer(mut stream: TcpStream, metrics: &Metrics) -> std::io::Result<()> {
    // A client that connects and says nothing must not hold the only serving thread.
    stream.set_read_timeout(Some(Duration::from_secs(2)))?;
    stream.set_write_timeout(Some(Duration::from_secs(2)))?;
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    let deadline = Instant::now() + REQUEST_DEADLINE;
    while !buf.windows(4).any(|w| w == b"\r\n\r\n") && buf.len() < 8192 {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "request not complete in time",
            ));
        }
        stream.set_read_timeout(Some(left))?;
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            break;
        }
        buf.extend_from_slice(&chunk[..n]);
    }
    let head = String::from_utf8_lossy(&buf);
    let mut words = head.lines().next().unwrap_or("").split_whitespace();
    let (method, target) = (words.next().unwrap_or(""), words.next().unwrap_or(""));
    let path = target.split('?').next().unwrap_or("");
    let (status, ctype, body) = match (method, path) {
        ("GET" | "HEAD", "/metrics") => ("200 OK", super::metrics::CONTENT_TYPE, metrics.render()),
        ("GET" | "HEAD", "/healthz") if metrics.stopping.load(Ordering::Relaxed) => {
            ("503 Service Unavailable", "text/plain", "stopping\n".into())
        }
        ("GET" | "HEAD", "/healthz")
            if metrics.queue_configured.load(Ordering::Relaxed)
                && metrics.queue_reachable.get() == 0 =>
        {
            (
                "503 Service Unavailable",
                "text/plain",
                "queue unreachable\n".into(),
            )
        }
        ("GET" | "HEAD", "/healthz") if metrics.queue_configured.load(Ordering::Relaxed) => {
            ("200 OK", "text/plain", "ok, queue reachable\n".into())
        }
        ("GET" | "HEAD", "/healthz") => ("200 OK", "text/plain", "ok\n".into()),
        ("GET" | "HEAD", _) => ("404 Not Found", "text/plain", "not found\n".into()),
        _ => ("405 Method Not Allowed", "text/plain", "GET only\n".into()),
    };
    let mut response = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .into_bytes();
    if method != "HEAD" {
        response.extend_from_slice(body.as_bytes());
    }
    stream.write_all(&response)?;
    stream.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn get(addr: std::net::SocketAddr, request: &str) -> String {
        let mut s = TcpStream::connect(addr).expect("connects");
        s.write_all(request.as_bytes()).expect("sends");
        let mut out = String::new();
        s.read_to_string(&mut out).expect("reads");
        out
    }

    #[test]
    fn answers_metrics_health_and_unknown_paths() {
        let m = Arc::new(Metrics::default());
        m.fitted.inc_by(3);
        let addr = serve("127.0.0.1:0", Arc::clone(&m)).expect("binds");
        let r = get(addr, "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n");
        assert!(r.starts_with("HTTP/1.1 200 OK"), "{r}");
        assert!(r.contains("trispline_patches_fitted_total 3"), "{r}");
        let r = get(addr, "GET /healthz HTTP/1.1\r\n\r\n");
        assert!(r.starts_with("HTTP/1.1 200") && r.ends_with("ok\n"), "{r}");
        let r = get(addr, "GET /nope HTTP/1.1\r\n\r\n");
        assert!(r.starts_with("HTTP/1.1 404"), "{r}");
        let r = get(addr, "POST /metrics HTTP/1.1\r\n\r\n");
        assert!(r.starts_with("HTTP/1.1 405"), "{r}");
        // With a cluster queue, health follows its connection.
        m.queue_configured.store(true, Ordering::Relaxed);
        let r = get(addr, "GET /healthz HTTP/1.1\r\n\r\n");
        assert!(
            r.starts_with("HTTP/1.1 503") && r.ends_with("queue unreachable\n"),
            "{r}"
        );
        m.queue_reachable.set(1);
        let r = get(addr, "GET /healthz HTTP/1.1\r\n\r\n");
        assert!(
            r.starts_with("HTTP/1.1 200") && r.ends_with("queue reachable\n"),
            "{r}"
        );
        m.stopping.store(true, Ordering::Relaxed);
        let r = get(addr, "GET /healthz HTTP/1.1\r\n\r\n");
        assert!(r.starts_with("HTTP/1.1 503"), "{r}");
    }

    /// Clients that connect and send part of a request (or nothing) and keep the connection
    /// open do not hold the health check: it is answered while they are still connected.
    #[test]
    fn a_silent_client_does_not_hold_health_checks() {
        let m = Arc::new(Metrics::default());
        let addr = serve("127.0.0.1:0", m).expect("binds");
        let mut silent: Vec<TcpStream> = (0..4)
            .map(|_| TcpStream::connect(addr).expect("connects"))
            .collect();
        silent[0].write_all(b"GET /heal").expect("sends part");
        let r = get(addr, "GET /healthz HTTP/1.1\r\n\r\n");
        assert!(r.starts_with("HTTP/1.1 200"), "{r}");
        // The slow clients are cut off by the deadline: their reads end (no hang).
        let mut rest = Vec::new();
        let _ = silent[0].read_to_end(&mut rest);
        assert!(rest.is_empty(), "no answer to a request never completed");
    }
}
