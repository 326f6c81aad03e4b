//! The event log `OUT/events.ndjson`: one JSON line per event, appended by the writer
//! thread alone. What a kill can leave of it, and its repair at start.

use std::path::Path;

/// A kill during an append can leave the event log's last line cut: a write that crosses a
/// page of the page cache may stop between pages on SIGKILL, so one `write` of a whole line
/// is not enough. Before the first append of a run the cut tail is moved to
/// `events.ndjson.torn` and the log ends at its last whole line, so that the next line
/// does not join the fragment. Returns the length of the fragment moved, if any.
pub(crate) fn repair_cut_tail(path: &Path) -> std::io::Result<Option<usize>> {
    use std::io::{Read, Seek, SeekFrom, Write};
    let mut log = match std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
    {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    let len = log.metadata()?.len();
    let (mut end, mut whole) = (len, 0u64);
    let mut chunk = vec![0u8; 64 * 1024];
    while end > 0 {
        let start = end.saturating_sub(chunk.len() as u64);
        let part = &mut chunk[..(end - start) as usize];
        log.seek(SeekFrom::Start(start))?;
        log.read_exact(part)?;
        if let Some(i) = part.iter().rposition(|&b| b == b'\n') {
            whole = start + i as u64 + 1;
            break;
        }
        end = start;
    }
    if whole == len {
        return Ok(None);
    }
    log.seek(SeekFrom::Start(whole))?;
    let mut cut = Vec::new();
    log.read_to_end(&mut cut)?;
    let mut torn = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path.with_extension("ndjson.torn"))?;
    torn.write_all(&[cut.as_slice(), b"\n"].concat())?;
    torn.sync_data()?;
    log.set_len(whole)?;
    log.sync_data()?;
    Ok(Some(cut.len()))
}

#[cfg(test)]
mod tests {
    use super::repair_cut_tail;

    #[test]
    fn a_cut_last_event_line_moves_to_the_torn_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let log = dir.path().join("events.ndjson");
        let torn = dir.path().join("events.ndjson.torn");
        // Absent, empty and whole logs stay as they are.
        assert_eq!(repair_cut_tail(&log).expect("absent"), None);
        std::fs::write(&log, "").expect("write");
        assert_eq!(repair_cut_tail(&log).expect("empty"), None);
        // Whole lines longer than the scan's chunk, then a cut one.
        let whole = format!("{{\"a\":\"{}\"}}\n{{\"b\":1}}\n", "x".repeat(100_000));
        std::fs::write(&log, &whole).expect("write");
        assert_eq!(repair_cut_tail(&log).expect("whole"), None);
        std::fs::write(&log, format!("{whole}{{\"c\":")).expect("write");
        assert_eq!(repair_cut_tail(&log).expect("cut"), Some(5));
        assert_eq!(std::fs::read_to_string(&log).expect("log"), whole);
        assert_eq!(std::fs::read_to_string(&torn).expect("torn"), "{\"c\":\n");
        // A log that is only a fragment ends up empty; the torn file keeps both fragments.
        std::fs::write(&log, "x".repeat(70_000)).expect("write");
        assert_eq!(repair_cut_tail(&log).expect("fragment"), Some(70_000));
        assert_eq!(std::fs::read(&log).expect("log").len(), 0);
        assert_eq!(
            std::fs::read_to_string(&torn).expect("torn").len(),
            6 + 70_001
        );
    }
}
