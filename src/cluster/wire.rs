//! What travels through the server: a job's framing, the per-patch record in the KV bucket
//! (claim, attempts, last committed version) and its warm-start state, and how a patch id
//! becomes a subject token and a key. Pure data and rules, no IO, so that the claim rules
//! can be tested alone.

use crate::daemon::state::PatchState;
use crate::io::Format;
use std::path::PathBuf;

/// The first bytes of every job: a version number of this framing.
const MAGIC: &[u8; 4] = b"TSJ1";

/// A job as published by a source.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct JobHeader {
    /// The patch id (sanitised as the daemon does).
    pub(crate) id: String,
    /// The version's name (the file name or the pipe record's).
    pub(crate) version: String,
    /// How the input is shown in events.
    pub(crate) label: String,
    /// `None` when the name has no known extension: the worker rejects it.
    pub(crate) format: Option<Format>,
    /// `content_hash` of the bytes, hex; empty when the source could not read them.
    pub(crate) hash: String,
    /// Set when the bytes are not in the message (over the payload limit, or unreadable at
    /// the source): the worker reads them here, on shared storage.
    pub(crate) path: Option<PathBuf>,
    /// The source that published it: a path job's completion goes back to it, which alone
    /// knows its folders and so may apply its processed-file policy. Empty: no completion.
    #[serde(default)]
    pub(crate) source: String,
    /// When the source handed it to the server, µs since the Unix epoch: the worker measures
    /// the queue's wait from it (the sources and workers of one site share a clock).
    #[serde(default)]
    pub(crate) published_us: u64,
}

/// What a worker tells a path job's source once the job is finished (its outputs written,
/// or its content found unchanged): the input file may now be moved or deleted.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Completion {
    pub(crate) id: String,
    pub(crate) version: String,
    pub(crate) path: PathBuf,
}

/// The message body: magic, header length (u32 LE), header JSON, mesh bytes.
pub(crate) fn encode(header: &JobHeader, body: &[u8]) -> Vec<u8> {
    let head = serde_json::to_vec(header).unwrap_or_default();
    let mut out = Vec::with_capacity(8 + head.len() + body.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&(head.len() as u32).to_le_bytes());
    out.extend_from_slice(&head);
    out.extend_from_slice(body);
    out
}

/// The header and the mesh bytes of a message, or why it is not a job.
pub(crate) fn decode(bytes: &[u8]) -> Result<(JobHeader, &[u8]), String> {
    let rest = bytes
        .strip_prefix(MAGIC.as_slice())
        .ok_or("not a trispline job (no TSJ1 magic)")?;
    let (len, rest) = rest
        .split_at_checked(4)
        .ok_or("cut before the header length")?;
    let len = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
    let (head, body) = rest
        .split_at_checked(len)
        .ok_or("header longer than the message")?;
    let header = serde_json::from_slice(head).map_err(|e| format!("bad job header: {e}"))?;
    Ok((header, body))
}

/// A patch id as one subject token and KV key part: ASCII letters, digits, `_` and `-`
/// stay, every other byte becomes `=XX` (hex). `=` never stays, so the mapping is
/// one-to-one, and the result holds no `.`, `*`, `>` or space.
pub(crate) fn token(id: &str) -> String {
    let mut out = String::with_capacity(id.len());
    for b in id.bytes() {
        if b.is_ascii_alphanumeric() || b == b'_' || b == b'-' {
            out.push(b as char);
        } else {
            out.push_str(&format!("={b:02X}"));
        }
    }
    out
}

/// A worker fitting a patch, until its claim runs out (renewed while it works).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Holder {
    pub(crate) worker: String,
    /// The stream sequence of the job being fitted.
    pub(crate) seq: u64,
    /// Unix time in ms after which another worker may take the patch.
    pub(crate) until_ms: u64,
}

/// A patch's record in the KV bucket; its revision is the compare-and-set token of every
/// change (claim, renewal, commit).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct PatchRecord {
    pub(crate) holder: Option<Holder>,
    /// The job whose fits were started `attempts` times (a worker dying mid-fit leaves the
    /// count behind; a poison input keeps raising it).
    pub(crate) attempt_seq: u64,
    pub(crate) attempts: u32,
    /// The newest job whose result is written (0: none).
    pub(crate) done_seq: u64,
    pub(crate) done_version: String,
    /// Whether the input of `done_seq` is finished (fitted or unchanged, not rejected): a
    /// redelivery of that job between its commit and its acknowledgement tells the source
    /// again, so a path job's file does not wait for the source's restart.
    #[serde(default)]
    pub(crate) done_finished: bool,
}

/// What a worker does with job `seq` given the patch's record.
#[derive(Debug, PartialEq)]
pub(crate) enum Decision {
    /// This job's result is already written (a redelivery after the commit): acknowledge.
    AlreadyDone,
    /// A newer version's result is written: this one is superseded by it.
    Superseded(String),
    /// Another worker fits the patch: try again shortly.
    Busy,
    /// Started this many times without finishing: quarantine.
    Poison(u32),
    /// Take the patch with this record.
    Claim(PatchRecord),
}

/// The claim rule: one fit per patch at a time, newest wins, poison after `max_attempts`.
pub(crate) fn decide(
    rec: &PatchRecord,
    seq: u64,
    me: &str,
    now_ms: u64,
    claim_ms: u64,
    max_attempts: u32,
) -> Decision {
    if rec.done_seq == seq {
        return Decision::AlreadyDone;
    }
    if rec.done_seq > seq {
        return Decision::Superseded(rec.done_version.clone());
    }
    if let Some(h) = &rec.holder {
        if h.until_ms > now_ms && h.worker != me {
            return Decision::Busy;
        }
    }
    let attempts = if rec.attempt_seq == seq {
        rec.attempts + 1
    } else {
        1
    };
    if attempts > max_attempts {
        return Decision::Poison(attempts - 1);
    }
    Decision::Claim(PatchRecord {
        holder: Some(Holder {
            worker: me.to_string(),
            seq,
            until_ms: now_ms + claim_ms,
        }),
        attempt_seq: seq,
        attempts,
        ..rec.clone()
    })
}

/// A patch's warm-start state in the KV bucket: inline under the payload limit, else a file
/// on shared storage (a 40k-point scan's state is ~2 MB of JSON).
#[derive(serde::Serialize, serde::Deserialize)]
pub(crate) enum StateRecord {
    Inline(Box<PatchState>),
    File(PathBuf),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jobs_round_trip_and_foreign_bytes_are_refused() {
        let h = JobHeader {
            id: "ear/left".into(),
            version: "ear@2.ply".into(),
            label: "/in/ear@2.ply".into(),
            format: Some(Format::Ply),
            hash: "00ff".into(),
            path: None,
            source: "host-1".into(),
            published_us: 1_700_000_000_000_000,
        };
        let body = b"ply\nformat ascii 1.0\n";
        let msg = encode(&h, body);
        let (back, rest) = decode(&msg).expect("decodes");
        assert_eq!(back, h);
        assert_eq!(rest, body);
        assert!(decode(b"hello").is_err());
        assert!(decode(&msg[..10]).is_err(), "cut header");
        let mut lying = msg.clone();
        lying[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode(&lying).is_err());
    }

    #[test]
    fn tokens_are_subject_safe_and_one_to_one() {
        let ids = ["ear", "ear.c0", "sub/ear", "sub=2Fear", "é", "a b", "a-b_c"];
        let tokens: Vec<String> = ids.iter().map(|i| token(i)).collect();
        for t in &tokens {
            assert!(t
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-' || b == b'='));
        }
        let distinct: std::collections::HashSet<_> = tokens.iter().collect();
        assert_eq!(distinct.len(), ids.len());
        assert_eq!(token("a-b_c"), "a-b_c");
    }

    #[test]
    fn claims_follow_one_fit_at_a_time_newest_wins_and_poison() {
        let free = PatchRecord::default();
        let Decision::Claim(a) = decide(&free, 5, "A", 1000, 300, 2) else {
            panic!("a free patch is claimed")
        };
        assert_eq!(a.attempts, 1);
        // B meets A's live claim, and takes it once it ran out (A died).
        assert_eq!(decide(&a, 5, "B", 1200, 300, 2), Decision::Busy);
        let Decision::Claim(b) = decide(&a, 5, "B", 1400, 300, 2) else {
            panic!("an expired claim is taken over")
        };
        assert_eq!(
            (b.attempts, b.holder.as_ref().map(|h| h.worker.as_str())),
            (2, Some("B"))
        );
        // B died too: the third start of the same job is refused as poison.
        assert_eq!(decide(&b, 5, "C", 2000, 300, 2), Decision::Poison(2));
        // A newer job starts counting again.
        assert!(matches!(decide(&b, 6, "C", 2000, 300, 2), Decision::Claim(r) if r.attempts == 1));
        let done = PatchRecord {
            done_seq: 9,
            done_version: "ear@9".into(),
            ..PatchRecord::default()
        };
        assert_eq!(decide(&done, 9, "A", 0, 300, 2), Decision::AlreadyDone);
        assert_eq!(
            decide(&done, 7, "A", 0, 300, 2),
            Decision::Superseded("ear@9".into())
        );
    }
}
