//! Operations: Prometheus metrics and health over a tiny loopback HTTP responder, and
//! systemd readiness notifications.

pub mod http;
pub mod metrics;
pub mod sdnotify;
