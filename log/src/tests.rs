//! Round trips through the writer and reader, damaged files, and real-log oddities.

use super::*;
use std::collections::BTreeMap;
use std::path::Path;

const JOINTS: [&str; 3] = ["hip", "knee", "ankle"];

fn joint_state(i: usize, stamp_nanos: i64) -> JointState {
    let t = i as f64 * 0.002;
    JointState {
        header: Header { stamp_nanos, frame_id: String::new() },
        name: JOINTS.iter().map(|s| s.to_string()).collect(),
        position: (0..3).map(|j| (t * (j + 1) as f64).sin()).collect(),
        velocity: (0..3).map(|j| (j + 1) as f64 * t).collect(),
        effort: (0..3).map(|j| -(j as f64) - t).collect(),
    }
}

/// Writes `n` JointStates at 500 Hz plus an IMU every 5th step.
fn write_log(path: &Path, n: usize, chunk_size_bytes: u64) -> u64 {
    let mut w = LogWriter::create(path, &WriterOptions { chunk_size_bytes, ..Default::default() }).unwrap();
    let js = w.add_topic::<JointState>("/joint_states").unwrap();
    let imu = w.add_topic::<Imu>("/imu").unwrap();
    let mut count = 0;
    for i in 0..n {
        let t = 1_000_000_000 + i as i64 * 2_000_000;
        w.write(js, t as u64, &joint_state(i, t)).unwrap();
        count += 1;
        if i % 5 == 0 {
            let m = Imu {
                header: Header { stamp_nanos: t, frame_id: "imu_link".into() },
                orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
                linear_acceleration: [0.0, 0.0, 9.81 + i as f64 * 1e-3],
                ..Default::default()
            };
            w.write(imu, t as u64, &m).unwrap();
            count += 1;
        }
    }
    let s = w.finish().unwrap();
    assert_eq!(s.messages, count);
    count
}

/// A log of 600 messages in 4 KiB chunks, written to `run.mcap` in `dir`, as the damage tests
/// start from.
struct ChunkedLog {
    dir: tempfile::TempDir,
    /// The file's bytes.
    bytes: Vec<u8>,
    /// Its chunks, as [`chunk_layout`] gives them.
    chunks: Vec<(u64, u64, u64)>,
    /// Messages written.
    total: u64,
}

fn chunked_log() -> ChunkedLog {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let total = write_log(&path, 600, 4096);
    let bytes = std::fs::read(&path).unwrap();
    let chunks = chunk_layout(&bytes);
    ChunkedLog { dir, bytes, chunks, total }
}

/// (start offset, end offset, message count) of every chunk, from the file's own summary.
fn chunk_layout(bytes: &[u8]) -> Vec<(u64, u64, u64)> {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    summary
        .chunk_indexes
        .iter()
        .map(|c| {
            let n: usize = summary.read_message_indexes(bytes, c).unwrap().values().map(Vec::len).sum();
            (c.chunk_start_offset, c.chunk_start_offset + c.chunk_length, n as u64)
        })
        .collect()
}

fn count_all(path: &Path, strict: bool) -> Result<(u64, ReadReport)> {
    let log = Log::open(path, ReadOptions { strict })?;
    let mut n = 0;
    let report = log.for_each_raw(&|_| true, |_| {
        n += 1;
        Ok(())
    })?;
    Ok((n, report))
}

#[test]
fn written_log_reads_back_with_same_values() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let total = write_log(&path, 1000, 1 << 20);
    let log = Log::open(&path, ReadOptions::default()).unwrap();
    let info = log.info().unwrap();
    assert_eq!(info.message_count, total);
    assert_eq!(info.profile, "ros2");
    assert_eq!(info.library, writer::LIBRARY_IDENTIFIER);
    let js_info = info.topics.iter().find(|t| t.topic == "/joint_states").unwrap();
    assert_eq!(js_info.count, 1000);
    assert!((js_info.rate_hz() - 500.0).abs() < 1e-6, "{}", js_info.rate_hz());
    assert_eq!(js_info.largest_gap_nanos, 2_000_000);
    assert_eq!(info.read.damage().count(), 0);

    let series = log.joint_states("/joint_states").unwrap();
    assert_eq!(series.names().collect::<Vec<_>>(), JOINTS);
    let knee = series.joint("knee").unwrap();
    assert_eq!(knee.len(), 1000);
    for i in [0, 17, 999] {
        let expected = joint_state(i, 0);
        assert_eq!(knee.time_nanos[i], 1_000_000_000 + i as i64 * 2_000_000);
        assert_eq!(knee.position[i], expected.position[1]);
        assert_eq!(knee.velocity[i], expected.velocity[1]);
        assert_eq!(knee.effort[i], expected.effort[1]);
    }
    assert!(series.report.warnings().is_empty(), "{:?}", series.report.warnings());

    let (imus, _) = log.read_typed::<Imu>("/imu").unwrap();
    assert_eq!(imus.len(), 200);
    assert_eq!(imus[3].1.linear_acceleration[2], 9.81 + 15.0 * 1e-3);
    assert_eq!(imus[3].1.header.frame_id, "imu_link");

    // The generic decoder agrees with the typed path.
    let mut values = Vec::new();
    log.for_each_value("/imu", |_, _, v| {
        values.push(v.get("linear_acceleration.z").and_then(Value::as_f64).unwrap());
        Ok(())
    })
    .unwrap();
    assert_eq!(values[3], 9.81 + 15.0 * 1e-3);

    let err = log.joint_states("/nope").unwrap_err().to_string();
    assert!(err.contains("/joint_states") && err.contains("/imu"), "{err}");
    let err = log.joint_states("/imu").unwrap_err().to_string();
    assert!(err.contains("sensor_msgs/msg/Imu"), "{err}");
}

#[test]
fn truncated_file_recovers_every_complete_chunk_exactly() {
    let ChunkedLog { dir, bytes, chunks, total } = chunked_log();
    assert!(chunks.len() > 10, "{} chunks", chunks.len());
    assert_eq!(chunks.iter().map(|c| c.2).sum::<u64>(), total);
    let data_end = chunks.last().unwrap().1;
    // Cuts inside chunks, at a chunk boundary, and inside the summary.
    let mid = |k: usize| (chunks[k].0 + chunks[k].1) / 2;
    let cuts =
        [mid(0), mid(1), chunks[3].1, chunks[3].1 + 3, mid(chunks.len() / 2), mid(chunks.len() - 1), data_end + 40];
    let cut_path = dir.path().join("cut.mcap");
    for &cut in &cuts {
        std::fs::write(&cut_path, &bytes[..cut as usize]).unwrap();
        let expected: u64 = chunks.iter().filter(|c| c.1 <= cut).map(|c| c.2).sum();
        let (n, report) = count_all(&cut_path, false).unwrap();
        assert_eq!(n, expected, "cut at {cut}");
        let warnings = report.warnings();
        assert!(!warnings.is_empty(), "cut at {cut} gave no warning");
        assert!(report.damage().any(|d| d.kind == DamageKind::Truncated), "cut at {cut}: {warnings:?}");
        if cut < data_end {
            // A cut inside a chunk says how many bytes of it were lost.
            let lost: u64 = report.damage().map(|d| d.lost_bytes).sum();
            let in_chunk = chunks.iter().find(|c| c.0 < cut && cut < c.1);
            if let Some(c) = in_chunk {
                assert_eq!(lost, cut - c.0, "cut at {cut}: {warnings:?}");
                assert!(warnings[0].contains("cut off inside a chunk"), "{warnings:?}");
            }
        }
        let strict = count_all(&cut_path, true).unwrap_err().to_string();
        assert!(strict.contains("--strict"), "{strict}");
    }
}

#[test]
fn bit_flipped_chunk_is_skipped_with_its_offset_or_refused() {
    let ChunkedLog { dir, mut bytes, chunks, total } = chunked_log();
    let k = chunks.len() / 2;
    let (start, end, lost) = chunks[k];
    // Flip a bit in the compressed data, well after the chunk header.
    let at = (end - 16) as usize;
    bytes[at] ^= 0x10;
    let flipped = dir.path().join("flipped.mcap");
    std::fs::write(&flipped, &bytes).unwrap();

    let (n, report) = count_all(&flipped, false).unwrap();
    assert_eq!(n, total - lost);
    let d: Vec<&Damage> = report.damage().collect();
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0].kind, DamageKind::CorruptChunk);
    assert_eq!(d[0].offset, start);
    assert_eq!(d[0].lost_messages, Some(lost));
    let text = report.warnings().join("\n");
    assert!(text.contains(&format!("byte {start}")), "{text}");
    assert!(text.contains(&format!("{} of the {total} messages", total - lost)), "{text}");

    let err = count_all(&flipped, true).unwrap_err().to_string();
    assert!(err.contains(&format!("byte {start}")), "{err}");

    // Joint series skip the chunk too and say so.
    let log = Log::open(&flipped, ReadOptions::default()).unwrap();
    let series = log.joint_states("/joint_states").unwrap();
    assert!(series.joint("hip").unwrap().len() < 600);
    assert!(!series.report.warnings().is_empty());
}

#[test]
fn garbage_and_missing_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.mcap");
    std::fs::write(&path, b"not an mcap at all").unwrap();
    let err = count_all(&path, false).unwrap_err().to_string();
    assert!(err.contains("not an MCAP file") && err.contains("x.mcap"), "{err}");
    let err = Log::open(dir.path().join("missing.mcap"), ReadOptions::default()).unwrap_err().to_string();
    assert!(err.contains("missing.mcap"), "{err}");
    // Every prefix of a valid file reads without panicking.
    let good = dir.path().join("good.mcap");
    write_log(&good, 50, 1024);
    let bytes = std::fs::read(&good).unwrap();
    for cut in (0..bytes.len()).step_by(7) {
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let _ = count_all(&path, false);
    }
    // And every single-byte corruption of it.
    for at in (0..bytes.len()).step_by(5) {
        let mut b = bytes.clone();
        b[at] = b[at].wrapping_add(0x5a);
        std::fs::write(&path, &b).unwrap();
        if let Ok(log) = Log::open(&path, ReadOptions::default()) {
            let _ = log.joint_states("/joint_states");
            let _ = log.info();
        }
    }
}

/// Real-log oddities: two publishers on one topic (arm and gripper, as two channels), names in
/// changing order, empty velocity/effort, zero and backwards stamps, a JSON channel.
#[test]
fn joint_states_merge_publishers_and_handle_real_log_oddities() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("real.mcap");
    let file = std::fs::File::create(&path).unwrap();
    let mut w = mcap::WriteOptions::new().profile("ros2").create(std::io::BufWriter::new(file)).unwrap();
    let schema = typed::schema_text(JointState::TYPE_NAME).unwrap();
    let sid = w.add_schema(JointState::TYPE_NAME, "ros2msg", schema.as_bytes()).unwrap();
    let mut meta = BTreeMap::new();
    let arm = w.add_channel(sid, "/joint_states", "cdr", &meta).unwrap();
    meta.insert("publisher".into(), "gripper".into());
    let gripper = w.add_channel(sid, "/joint_states", "cdr", &meta).unwrap();
    let json = w.add_channel(0, "/json_states", "json", &meta).unwrap();
    let write = |w: &mut mcap::Writer<_>, ch: u16, log_time: u64, js: &JointState| {
        let mut c = cdr::CdrWriter::new();
        js.encode(&mut c);
        w.write_to_known_channel(
            &mcap::records::MessageHeader { channel_id: ch, sequence: 0, log_time, publish_time: log_time },
            c.bytes(),
        )
        .unwrap();
    };
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    // Arm: names swap order in the second message; velocity empty in the third.
    let msgs = [
        (arm, 100, 10, s(&["a1", "a2"]), vec![1.0, 2.0], vec![0.1, 0.2]),
        (gripper, 105, 0, s(&["g"]), vec![0.05], vec![]),
        (arm, 110, 20, s(&["a2", "a1"]), vec![2.5, 1.5], vec![0.3, 0.4]),
        (arm, 120, 15, s(&["a1", "a2"]), vec![1.7, 2.7], vec![]),
        (gripper, 125, 0, s(&["g"]), vec![0.06], vec![]),
    ];
    for (ch, log_time, stamp, name, position, velocity) in &msgs {
        let js = JointState {
            header: Header { stamp_nanos: *stamp, frame_id: String::new() },
            name: name.clone(),
            position: position.clone(),
            effort: if *ch == gripper { vec![] } else { vec![9.0, 8.0] },
            velocity: velocity.clone(),
        };
        write(&mut w, *ch, *log_time, &js);
    }
    let json_msg = br#"{"header":{"stamp":{"sec":1,"nsec":5},"frame_id":""},"name":["x"],"position":[0.25],"velocity":[null],"effort":[]}"#;
    w.write_to_known_channel(
        &mcap::records::MessageHeader { channel_id: json, sequence: 0, log_time: 7, publish_time: 7 },
        json_msg,
    )
    .unwrap();
    w.finish().unwrap();
    drop(w);

    let log = Log::open(&path, ReadOptions::default()).unwrap();
    let series = log.joint_states("/joint_states").unwrap();
    assert_eq!(series.names().collect::<Vec<_>>(), ["a1", "a2", "g"]);
    let a1 = series.joint("a1").unwrap();
    // Stamps 10, 20, 15 -> sorted 10, 15, 20.
    assert_eq!(a1.time_nanos, [10, 15, 20]);
    assert_eq!(a1.position, [1.0, 1.7, 1.5]);
    assert_eq!(a1.velocity[0], 0.1);
    assert!(a1.velocity[1].is_nan());
    assert_eq!(a1.velocity[2], 0.4);
    let g = series.joint("g").unwrap();
    assert_eq!(g.time_nanos, [105, 125]); // zero stamps -> log time
    assert_eq!(g.position, [0.05, 0.06]);
    assert!(!g.has_velocity() && !g.has_effort());
    let r = &series.report;
    assert_eq!(r.messages, 5);
    assert_eq!(r.channels, 2);
    assert_eq!(r.zero_stamps, 2);
    assert_eq!(r.non_monotonic, 2); // a1 and a2 each went back once
    assert_eq!(r.empty_velocity, 3);
    assert_eq!(r.name_sets.len(), 3);
    let warnings = r.warnings().join("\n");
    assert!(warnings.contains("zero header stamp") && warnings.contains("several publishers"));

    let js = log.joint_states("/json_states").unwrap();
    let x = js.joint("x").unwrap();
    assert_eq!(x.time_nanos, [1_000_000_005]);
    assert_eq!(x.position, [0.25]);
    assert!(x.velocity[0].is_nan());

    let info = log.info().unwrap();
    let t = info.topics.iter().find(|t| t.topic == "/joint_states").unwrap();
    assert_eq!((t.count, t.channels, t.largest_gap_nanos), (5, 2, 10));
}

#[test]
fn rosbag2_folder_is_read_through_its_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    std::fs::create_dir(&bag).unwrap();
    write_log(&bag.join("bag_0.mcap"), 10, 1 << 20);
    write_log(&bag.join("bag_1.mcap"), 5, 1 << 20);
    std::fs::write(
        bag.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  \
         relative_file_paths:\n    - bag_0.mcap\n    - bag_1.mcap\n  duration:\n    nanoseconds: 1\n",
    )
    .unwrap();
    let log = Log::open(&bag, ReadOptions::default()).unwrap();
    assert_eq!(log.files().len(), 2);
    assert_eq!(log.joint_states("/joint_states").unwrap().joints[0].len(), 15);
    std::fs::write(bag.join("metadata.yaml"), "rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n").unwrap();
    let err = Log::open(&bag, ReadOptions::default()).unwrap_err().to_string();
    assert!(err.contains("sqlite3") && err.contains("ros2 bag convert"), "{err}");
}

/// The shipped fixture (written by `mcap-ros2-support`, see data/make_fixtures.py) reads back
/// with the humanoid's 23 joints and the values of the generating formula.
#[test]
fn humanoid_fixture_reads_with_the_generating_formula() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/humanoid_joint_states.mcap");
    let log = Log::open(path, ReadOptions::default()).unwrap();
    let series = log.joint_states("/joint_states").unwrap();
    let urdf = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap();
    let doc = roxmltree::Document::parse(&urdf).unwrap();
    let names: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("joint") && n.attribute("type") == Some("revolute"))
        .filter_map(|n| n.attribute("name"))
        .collect();
    assert_eq!(series.names().collect::<Vec<_>>(), names);
    assert_eq!(series.report.empty_effort, 20);
    for (k, j) in series.joints.iter().enumerate() {
        assert_eq!(j.len(), 200);
        let q0 = if j.name.contains("knee") {
            0.3
        } else if j.name.contains("hip_pitch") || j.name.contains("ankle_pitch") {
            -0.15
        } else {
            0.0
        };
        for i in [0usize, 1, 77, 199] {
            let t = i as f64 / 100.0;
            let ph = 2.0 * std::f64::consts::PI * 0.5 * t + 0.3 * k as f64;
            assert_eq!(j.time_nanos[i], 1_700_000_000_000_000_000 + i as i64 * 10_000_000);
            assert!((j.position[i] - (q0 + 0.05 * ph.sin())).abs() < 1e-12);
            assert!((j.velocity[i] - 0.05 * std::f64::consts::PI * ph.cos()).abs() < 1e-12);
            if i % 10 == 0 {
                assert!(j.effort[i].is_nan());
            } else {
                assert!((j.effort[i] - (2.0 + 0.5 * k as f64 + ph.sin())).abs() < 1e-12);
            }
        }
    }
}

/// A chunk cut mid-write gives back its complete messages: exactly those whose record lies
/// wholly before the cut (uncompressed chunks), at least the complete chunks' (zstd).
#[test]
fn partial_chunk_messages_are_salvaged() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("raw.mcap");
    let mut w = LogWriter::create(
        &path,
        &WriterOptions {
            chunk_size_bytes: 16 * 1024,
            compression: super::writer::Compression::None,
            ..Default::default()
        },
    )
    .unwrap();
    let js = w.add_topic::<JointState>("/joint_states").unwrap();
    for i in 0..300 {
        w.write(js, i as u64, &joint_state(i, i as i64 + 1)).unwrap();
    }
    w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    // Absolute end offset of every message record, from the message indexes.
    let mut ends = Vec::new();
    for c in &summary.chunk_indexes {
        // Records start after opcode+len (9) and the chunk header (8+8+8+4+4+0+8 = 40).
        let records_start = c.chunk_start_offset + 9 + 40;
        for entries in summary.read_message_indexes(&bytes, c).unwrap().values() {
            for e in entries {
                let at = (records_start + e.offset) as usize;
                let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap());
                ends.push(at as u64 + 9 + len);
            }
        }
    }
    assert_eq!(ends.len(), 300);
    let cut_path = dir.path().join("cut.mcap");
    let c1 = &summary.chunk_indexes[1];
    for cut in [
        c1.chunk_start_offset + 200,
        c1.chunk_start_offset + c1.chunk_length / 2,
        c1.chunk_start_offset + c1.chunk_length - 3,
    ] {
        std::fs::write(&cut_path, &bytes[..cut as usize]).unwrap();
        let expected = ends.iter().filter(|&&e| e <= cut).count() as u64;
        let (n, report) = count_all(&cut_path, false).unwrap();
        assert_eq!(n, expected, "cut at {cut}");
        assert!(report.warnings()[0].contains("recovered from it"), "{:?}", report.warnings());
    }

    // zstd: twin's own 1 MiB chunks decode block by block.
    let zpath = dir.path().join("z.mcap");
    write_log(&zpath, 3000, 1 << 20);
    let zbytes = std::fs::read(&zpath).unwrap();
    let chunks = chunk_layout(&zbytes);
    let (start, end, in_chunk) = chunks[0];
    let cut = (start + end) / 2;
    std::fs::write(&cut_path, &zbytes[..cut as usize]).unwrap();
    let (n, report) = count_all(&cut_path, false).unwrap();
    eprintln!("zstd salvage: {n} of {in_chunk}: {:?}", report.warnings());
    assert!(n < in_chunk);
}

#[test]
fn inline_and_background_writers_write_the_same_bytes_and_lz4_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, options: WriterOptions| {
        let path = dir.path().join(name);
        let mut w = LogWriter::create(&path, &WriterOptions { chunk_size_bytes: 64 * 1024, ..options }).unwrap();
        let js = w.add_topic::<JointState>("/joint_states").unwrap();
        for i in 0..3000 {
            let t = i as i64 * 2_000_000;
            w.write(js, t as u64, &joint_state(i, t)).unwrap();
            if i == 1500 {
                // A topic added mid-run lands after the messages batched before it.
                let late = w.add_topic::<WrenchStamped>("/late").unwrap();
                w.write(late, t as u64, &WrenchStamped { force: [1.0, 2.0, 3.0], ..Default::default() }).unwrap();
            }
        }
        assert_eq!(w.finish().unwrap().messages, 3001);
        path
    };
    let background = write("bg.mcap", WriterOptions::default());
    let inline = write("inline.mcap", WriterOptions { background: false, ..Default::default() });
    assert_eq!(std::fs::read(&background).unwrap(), std::fs::read(&inline).unwrap());
    let lz4 = write("lz4.mcap", WriterOptions { compression: writer::Compression::Lz4, ..Default::default() });
    for path in [&background, &lz4] {
        let log = Log::open(path, ReadOptions { strict: true }).unwrap();
        let (msgs, _) = log.read_typed::<JointState>("/joint_states").unwrap();
        assert_eq!(msgs.len(), 3000);
        assert_eq!(msgs[2999].1, joint_state(2999, 2999 * 2_000_000));
        let (late, _) = log.read_typed::<WrenchStamped>("/late").unwrap();
        assert_eq!((late.len(), late[0].0), (1, 1500 * 2_000_000));
    }
}

/// File offset of the data-end record, walking the records from the start.
fn data_end_offset(bytes: &[u8]) -> usize {
    let mut pos = 8;
    loop {
        let opcode = bytes[pos];
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        if opcode == mcap::records::op::DATA_END {
            return pos;
        }
        pos += 9 + len;
    }
}

/// Issue 15: `log info --strict` accepted files cut inside the summary, the footer or the end
/// magic. Every cut from the data-end record to the last byte of the shipped logs (and of one
/// twin writes) is refused by a strict reader and reported as cut (all messages kept) by a
/// lenient one; only the whole file is complete.
#[test]
fn cuts_anywhere_in_the_summary_footer_or_magic_are_not_complete() {
    let dir = tempfile::tempdir().unwrap();
    let written = dir.path().join("run.mcap");
    write_log(&written, 300, 4096);
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data");
    let cut_path = dir.path().join("cut.mcap");
    let mut cuts = 0;
    for file in [written, data.join("humanoid_joint_states.mcap"), data.join("arm6_identification.mcap")] {
        let bytes = std::fs::read(&file).unwrap();
        let whole = Log::open(&file, ReadOptions { strict: true }).unwrap().info().unwrap();
        assert!(whole.read.files.iter().all(|(_, r)| r.has_summary), "{}", file.display());
        assert!(whole.read.damage().next().is_none(), "{}", file.display());
        let start = data_end_offset(&bytes);
        assert!(bytes.len() - start > 100, "{}: a summary section to cut", file.display());
        // Every byte of the tail; for the 1.3 MB arm log (slow to reread in debug builds), every
        // 7th byte of its summary and every byte of its footer and magic.
        let step = if bytes.len() > 1 << 20 { 7 } else { 1 };
        let footer = bytes.len() - 37;
        for cut in (start..footer).step_by(step).chain(footer..bytes.len()) {
            std::fs::write(&cut_path, &bytes[..cut]).unwrap();
            let strict = Log::open(&cut_path, ReadOptions { strict: true }).and_then(|l| l.info());
            let err = match strict {
                Ok(_) => panic!("{} cut at byte {cut} of {} accepted as complete", file.display(), bytes.len()),
                Err(e) => e.to_string(),
            };
            // Past the data-end record (13 bytes), the message names what was not closed.
            assert!(err.contains("--strict"), "cut {cut}: {err}");
            assert!(cut < start + 13 || err.contains("not closed cleanly"), "cut {cut}: {err}");
            if cut % 16 != 0 {
                cuts += 1;
                continue;
            }
            let lenient = Log::open(&cut_path, ReadOptions { strict: false }).unwrap().info().unwrap();
            assert_eq!(lenient.message_count, whole.message_count, "cut {cut}: every message is before the cut");
            assert!(lenient.read.damage().any(|d| d.kind == DamageKind::Truncated), "cut {cut}");
            cuts += 1;
        }
    }
    assert!(cuts > 2000, "{cuts} cuts");
}
