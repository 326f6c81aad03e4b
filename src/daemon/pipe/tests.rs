//! The pipe reader alone: line framing, a bad length's resynchronisation, the payload
//! budget.

use super::*;

#[test]
fn lines_are_bounded_and_framing_survives_a_long_one() {
    let mut input = vec![b'x'; MAX_LINE + 10];
    input.extend_from_slice(b"\n{\"a\":1}\nlast");
    let mut r = std::io::BufReader::with_capacity(1000, input.as_slice());
    assert!(matches!(read_line(&mut r).expect("reads"), Line::TooLong));
    assert!(matches!(read_line(&mut r).expect("reads"), Line::Text(t) if t == b"{\"a\":1}"));
    assert!(matches!(read_line(&mut r).expect("reads"), Line::Text(t) if t == b"last"));
    assert!(matches!(read_line(&mut r).expect("reads"), Line::Eof));
}

struct Rig {
    source: PipeSource,
    arrivals: crossbeam_channel::Receiver<Msg>,
    writer: crossbeam_channel::Receiver<WriterMsg>,
    _tmp: tempfile::TempDir,
}

fn rig(max_file_bytes: u64) -> Rig {
    let tmp = tempfile::tempdir().expect("tmp");
    let mut cfg = super::super::config::DaemonConfig::embedded_default().expect("config");
    cfg.daemon.max_file_bytes = max_file_bytes;
    let (tx, arrivals) = crossbeam_channel::unbounded();
    let (wtx, writer) = crossbeam_channel::unbounded();
    let source = PipeSource {
        spec: PipeSpec::Stdin,
        cell: Arc::new(ConfigCell::new(cfg)),
        once: true,
        tx,
        writer: wtx,
        stop: Arc::new(AtomicBool::new(false)),
        quarantine: tmp.path().join("quarantine"),
        watch_dir: tmp.path().to_path_buf(),
        partial: Arc::default(),
        held: RefCell::default(),
    };
    Rig {
        source,
        arrivals,
        writer,
        _tmp: tmp,
    }
}

fn inline(patch: &str, bytes: &[u8]) -> Vec<u8> {
    let mut r = format!(
        "{{\"patch\": \"{patch}\", \"format\": \"obj\", \"bytes\": {}}}\n",
        bytes.len()
    )
    .into_bytes();
    r.extend_from_slice(bytes);
    r
}

/// `"bytes": 1e30` and then a 64 KB OBJ: one rejection, one quarantine file holding the
/// header and the skipped bytes, and the record after it is read normally.
#[test]
fn a_bad_length_skips_its_record_exactly_once() {
    let rig = rig(1 << 20);
    let obj: String = (0..4000).map(|k| format!("v {k} 0 0\n")).collect();
    let mut input = b"{\"patch\": \"bad\", \"format\": \"obj\", \"bytes\": 1e30}\n".to_vec();
    input.extend_from_slice(obj.as_bytes());
    input.extend_from_slice(&inline("good", b"v 0 0 0\n"));
    let mut r = std::io::BufReader::with_capacity(4096, input.as_slice());
    let mut n = 0;
    rig.source.records(&mut r, "test", &mut n);
    let rejects: Vec<WriterMsg> = rig.writer.try_iter().collect();
    assert_eq!(rejects.len(), 1, "one rejection");
    let WriterMsg::Reject { kind, keep, .. } = &rejects[0] else {
        panic!("a rejection");
    };
    assert_eq!(*kind, "record_bad_length");
    let Keep::Already(file) = keep else {
        panic!("kept in quarantine");
    };
    let kept = std::fs::read(file).expect("quarantined");
    assert!(kept.ends_with(obj.as_bytes()), "the skipped bytes are kept");
    let files = std::fs::read_dir(&rig.source.quarantine)
        .expect("dir")
        .count();
    assert_eq!(files, 1, "one quarantine file");
    let arrived: Vec<String> = rig
        .arrivals
        .try_iter()
        .filter_map(|m| match m {
            Msg::Arrivals(a) => Some(a.into_iter().map(|a| a.id)),
            _ => None,
        })
        .flatten()
        .collect();
    assert_eq!(arrived, ["good"]);
    assert_eq!(n, 2, "two records");
}

/// Payloads handed on and still held count against the budget: with two held, the
/// reader does not take the third record until they are let go.
#[test]
fn the_reader_stops_while_the_payload_budget_is_full() {
    let rig = rig(1000);
    let (source, arrivals) = (rig.source, rig.arrivals);
    let stop = Arc::clone(&source.stop);
    let mut input = Vec::new();
    for k in 0..3 {
        input.extend_from_slice(&inline(&format!("p{k}"), &[b'v'; 400]));
    }
    let reader = std::thread::spawn(move || {
        let mut r = std::io::BufReader::with_capacity(64, input.as_slice());
        let mut n = 0;
        source.records(&mut r, "test", &mut n);
        n
    });
    let mut held = Vec::new();
    for _ in 0..2 {
        match arrivals.recv_timeout(Duration::from_secs(60)) {
            Ok(Msg::Arrivals(a)) => held.extend(a),
            _ => panic!("two records arrive"),
        }
    }
    // 400 + 400 held; 400 more would pass the budget of 1000.
    assert!(
        arrivals.recv_timeout(Duration::from_millis(300)).is_err(),
        "the third record waits for the budget"
    );
    drop(held);
    match arrivals.recv_timeout(Duration::from_secs(60)) {
        Ok(Msg::Arrivals(a)) => assert_eq!(a[0].id, "p2"),
        _ => panic!("the third record arrives once memory is let go"),
    }
    stop.store(true, Ordering::Relaxed);
    assert_eq!(reader.join().expect("reader"), 3);
}

#[test]
fn an_object_record_needs_an_id_and_a_rigid_transform_of_16_numbers() {
    let parse = |text: &str| record_object(&serde_json::from_str(text).expect("json"));
    assert_eq!(parse(r#"{"patch": "a"}"#), Ok(None));
    assert_eq!(
        parse(r#"{"patch": "a", "object": "bunny"}"#),
        Ok(Some(("bunny".to_string(), None)))
    );
    let turn = r#"[0, -1, 0, 0.5, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"#;
    let (id, m) = parse(&format!(
        r#"{{"patch": "a", "object": "bunny", "transform": {turn}}}"#
    ))
    .expect("valid")
    .expect("an object");
    assert_eq!(id, "bunny");
    assert_eq!(m.map(|m| m[3]), Some(0.5));
    for bad in [
        format!(r#"{{"patch": "a", "transform": {turn}}}"#),
        r#"{"patch": "a", "object": ""}"#.to_string(),
        r#"{"patch": "a", "object": 3}"#.to_string(),
        r#"{"patch": "a", "object": "o", "transform": [1, 0, 0]}"#.to_string(),
        r#"{"patch": "a", "object": "o", "transform": "identity"}"#.to_string(),
        // A scaling, and a mirror: no rigid motions.
        r#"{"patch": "a", "object": "o", "transform": [2,0,0,0, 0,2,0,0, 0,0,2,0, 0,0,0,1]}"#
            .to_string(),
        r#"{"patch": "a", "object": "o", "transform": [-1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}"#
            .to_string(),
    ] {
        assert!(parse(&bad).is_err(), "{bad}");
    }
}

#[test]
fn an_object_record_goes_to_the_writer_not_the_scheduler() {
    let rig = rig(1 << 20);
    let ply = b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n";
    let mut input = format!(
        "{{\"object\": \"o\", \"patch\": \"s\", \"format\": \"ply\", \"bytes\": {}}}\n",
        ply.len()
    )
    .into_bytes();
    input.extend_from_slice(ply);
    let mut record = 0;
    rig.source
        .records(&mut input.as_slice(), "test", &mut record);
    assert!(
        rig.arrivals.try_recv().is_err(),
        "no arrival before the scan is stored"
    );
    match rig.writer.try_recv() {
        Ok(WriterMsg::ObjectScan(s)) => {
            assert_eq!((s.object.as_str(), s.scan.id.as_str()), ("o", "s"));
            assert!(s.transform.is_none());
        }
        _ => panic!("the writer gets the scan"),
    }
}
