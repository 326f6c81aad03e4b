//! The `[cluster]` table: where the shared work queue and warm-start store live when
//! several daemons and workers share the work (`watch --queue`, `worker --queue`).

use std::path::PathBuf;

/// The `[cluster]` table. Without a URL (and without `--queue`) the daemon fits locally.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterSection {
    /// `nats://HOST:PORT` of a NATS server with JetStream; `--queue` overrides it.
    #[serde(default)]
    pub url: Option<String>,
    /// The work-queue stream's name.
    #[serde(default = "default_stream")]
    pub stream: String,
    /// The subject prefix of jobs: one subject per patch below it.
    #[serde(default = "default_subject")]
    pub subject: String,
    /// The key-value bucket holding each patch's claim and warm-start state.
    #[serde(default = "default_bucket")]
    pub bucket: String,
    /// A NATS credentials file (JWT and NKey seed), when the server asks for one.
    #[serde(default)]
    pub credentials: Option<PathBuf>,
    /// Mesh bytes and states up to this size travel through the server; larger ones are
    /// left on shared storage and only their path travels (NATS' default message limit is
    /// 1 MiB, and large objects in JetStream are fragile).
    #[serde(default = "default_payload_limit")]
    pub payload_limit: usize,
    /// A version whose fit was started this many times without finishing (the worker died
    /// each time) is quarantined as poison instead of being tried again.
    #[serde(default = "default_max_deliveries")]
    pub max_deliveries: u32,
    /// A job not acknowledged (nor kept alive by a worker's progress) for this long goes to
    /// another worker.
    #[serde(default = "default_ack_wait_ms")]
    pub ack_wait_ms: u64,
}

impl Default for ClusterSection {
    fn default() -> Self {
        Self {
            url: None,
            stream: default_stream(),
            subject: default_subject(),
            bucket: default_bucket(),
            credentials: None,
            payload_limit: default_payload_limit(),
            max_deliveries: default_max_deliveries(),
            ack_wait_ms: default_ack_wait_ms(),
        }
    }
}

fn default_stream() -> String {
    "TRISPLINE_JOBS".into()
}

fn default_subject() -> String {
    "trispline.jobs".into()
}

fn default_bucket() -> String {
    "trispline".into()
}

fn default_payload_limit() -> usize {
    512 * 1024
}

fn default_max_deliveries() -> u32 {
    3
}

fn default_ack_wait_ms() -> u64 {
    30_000
}

/// Why a `[cluster]` value is refused: (key, value, rule).
pub(crate) type Refusal = (&'static str, String, &'static str);

/// Ranges and name rules of `[cluster]`.
pub(crate) fn validate_cluster(c: &ClusterSection) -> Result<(), Refusal> {
    let name_ok = |s: &str| {
        !s.is_empty()
            && s.bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
    };
    if !name_ok(&c.stream) {
        return Err((
            "cluster.stream",
            c.stream.clone(),
            "letters, digits, _ and - only",
        ));
    }
    if !name_ok(&c.bucket) {
        return Err((
            "cluster.bucket",
            c.bucket.clone(),
            "letters, digits, _ and - only",
        ));
    }
    let subject_ok = c.subject.split('.').all(name_ok);
    if !subject_ok {
        return Err((
            "cluster.subject",
            c.subject.clone(),
            "dot-separated tokens of letters, digits, _ and -",
        ));
    }
    if let Some(url) = &c.url {
        if !(url.starts_with("nats://") || url.starts_with("tls://")) {
            return Err((
                "cluster.url",
                url.clone(),
                "must start with nats:// or tls://",
            ));
        }
    }
    if !(1024..=64 * 1024 * 1024).contains(&c.payload_limit) {
        return Err((
            "cluster.payload_limit",
            c.payload_limit.to_string(),
            "must be 1024..=67108864 bytes",
        ));
    }
    if !(1..=100).contains(&c.max_deliveries) {
        return Err((
            "cluster.max_deliveries",
            c.max_deliveries.to_string(),
            "must be 1..=100",
        ));
    }
    if !(500..=3_600_000).contains(&c.ack_wait_ms) {
        return Err((
            "cluster.ack_wait_ms",
            c.ack_wait_ms.to_string(),
            "must be 500..=3600000",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_pass_and_bad_names_and_ranges_are_named() {
        assert!(validate_cluster(&ClusterSection::default()).is_ok());
        let bad = |f: &dyn Fn(&mut ClusterSection)| {
            let mut c = ClusterSection::default();
            f(&mut c);
            validate_cluster(&c).err().map(|e| e.0)
        };
        assert_eq!(bad(&|c| c.stream = "a.b".into()), Some("cluster.stream"));
        assert_eq!(bad(&|c| c.subject = "a..b".into()), Some("cluster.subject"));
        assert_eq!(bad(&|c| c.subject = "a.*".into()), Some("cluster.subject"));
        assert_eq!(
            bad(&|c| c.url = Some("http://x".into())),
            Some("cluster.url")
        );
        assert_eq!(
            bad(&|c| c.max_deliveries = 0),
            Some("cluster.max_deliveries")
        );
        assert_eq!(bad(&|c| c.ack_wait_ms = 10), Some("cluster.ack_wait_ms"));
        assert_eq!(
            bad(&|c| c.payload_limit = 10),
            Some("cluster.payload_limit")
        );
        assert_eq!(bad(&|c| c.url = Some("nats://127.0.0.1:4222".into())), None);
    }
}
