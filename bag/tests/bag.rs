//! Writer and reader together: round trips, ordering, crash safety, damaged files and errors.

use std::path::{Path, PathBuf};

use dynlab_bag::{Bag, BagError, BagWriter, Compression, QosProfile, WriterOptions};
use dynlab_msgs::RosMessage;
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_msgs::std_msgs::Header;

fn pose(i: u64) -> PoseStamped {
    let mut p = PoseStamped::default();
    p.header.stamp = Time::from_nanos(i as i64 * 10_000_000);
    p.header.frame_id = format!("frame{}", i % 3);
    p.pose.position.x = i as f64 * 0.5;
    p.pose.position.y = -(i as f64) * 0.25;
    p.pose.orientation.z = (i as f64 * 0.01).sin();
    p.pose.orientation.w = (i as f64 * 0.01).cos();
    p
}

fn header(i: u64) -> Header {
    Header {
        stamp: Time::from_nanos(i as i64),
        frame_id: format!("h{i}"),
    }
}

const T0: u64 = 1_700_000_000_000_000_000;

/// Writes `n` poses at 100 Hz on /car/pose and a header every 10th step on /car/cmd.
fn write_bag(dir: &Path, n: u64, options: WriterOptions) -> u64 {
    let mut w = BagWriter::create(dir, options).unwrap();
    let p = w
        .add_typed_topic::<PoseStamped>("/car/pose", &[QosProfile::sensor_data()])
        .unwrap();
    let c = w
        .add_typed_topic::<Header>("/car/cmd", &[QosProfile::default_profile()])
        .unwrap();
    let mut count = 0;
    for i in 0..n {
        let t = T0 + i * 10_000_000;
        w.write(p, t, &pose(i)).unwrap();
        count += 1;
        if i % 10 == 0 {
            w.write(c, t + 1, &header(i)).unwrap();
            count += 1;
        }
    }
    let summary = w.finish().unwrap();
    assert_eq!(summary.message_count, count);
    count
}

fn mcap_in(dir: &Path) -> PathBuf {
    dir.join(format!(
        "{}_0.mcap",
        dir.file_name().unwrap().to_str().unwrap()
    ))
}

#[test]
fn round_trip_keeps_every_value_type_qos_and_hash() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run1");
    let count = write_bag(&dir, 500, WriterOptions::default());
    let bag = Bag::open(&dir).unwrap();
    assert!(bag.recovery().is_none(), "{:?}", bag.recovery());
    assert_eq!(bag.message_count(), count);
    let poses = bag.read::<PoseStamped>("/car/pose").unwrap();
    assert_eq!(poses.len(), 500);
    for (i, s) in poses.iter().enumerate() {
        assert_eq!(s.msg, pose(i as u64));
        assert_eq!(s.log_time_ns, T0 + i as u64 * 10_000_000);
        assert_eq!(s.publish_time_ns, s.log_time_ns);
    }
    let cmds = bag.read::<Header>("/car/cmd").unwrap();
    assert_eq!(
        cmds.iter().map(|s| s.msg.clone()).collect::<Vec<_>>(),
        (0..500).step_by(10).map(header).collect::<Vec<_>>()
    );

    let info = bag.info();
    let topic = &info.topics[0];
    assert_eq!(topic.name, "/car/pose");
    assert_eq!(topic.type_name, PoseStamped::TYPE_NAME);
    assert_eq!(topic.schema_encoding, "ros2msg");
    assert_eq!(topic.message_encoding, "cdr");
    assert_eq!(topic.definition, PoseStamped::definition());
    assert_eq!(topic.qos, vec![QosProfile::sensor_data()]);
    // Reference value: rosbags' Jazzy type store (hash_rihs01), an independent implementation.
    assert_eq!(
        topic.type_hash,
        "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
    );
    assert!((topic.rate_hz().unwrap() - 100.0).abs() < 1e-9);
    assert_eq!(info.topics[1].qos, vec![QosProfile::default_profile()]);
    assert_eq!(info.start_ns, Some(T0));
    assert_eq!(info.duration_ns, 499 * 10_000_000);
    assert!(info.files[0].complete);
    let table = info.to_string();
    assert!(
        table.contains("/car/pose") && table.contains("100.00"),
        "{table}"
    );

    // metadata.yaml agrees with the data.
    let meta = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
    assert!(
        meta.starts_with(
            "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n"
        )
    );
    assert!(
        meta.contains(&format!("  message_count: {count}\n")),
        "{meta}"
    );
    assert!(
        meta.contains("  relative_file_paths:\n    - run1_0.mcap\n"),
        "{meta}"
    );
    assert!(meta.contains("  ros_distro: jazzy\n"));
}

#[test]
fn uncompressed_bags_round_trip_and_a_bare_mcap_file_opens() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("plain");
    let options = WriterOptions {
        compression: Compression::None,
        ..Default::default()
    };
    let count = write_bag(&dir, 50, options);
    let bag = Bag::open(mcap_in(&dir)).unwrap();
    assert_eq!(bag.message_count(), count);
    assert_eq!(
        bag.read::<PoseStamped>("/car/pose").unwrap()[49].msg,
        pose(49)
    );
    assert!(bag.recovery().is_none());
}

#[test]
fn messages_are_time_ordered_across_topics_written_out_of_order() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("order");
    let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    let a = w.add_typed_topic::<Header>("/a", &[]).unwrap();
    let b = w.add_typed_topic::<Header>("/b", &[]).unwrap();
    // (topic, log time, tag); ties at 20 must keep write order.
    let writes = [
        (a, 30, 0),
        (b, 20, 1),
        (a, 10, 2),
        (b, 5, 3),
        (a, 20, 4),
        (b, 40, 5),
        (a, 20, 6),
    ];
    for (t, time, tag) in writes {
        w.write(t, time, &header(tag)).unwrap();
        if tag == 3 {
            w.flush().unwrap(); // split across chunks too
        }
    }
    w.finish().unwrap();
    let bag = Bag::open(&dir).unwrap();
    let got: Vec<(String, u64, String)> = bag
        .messages()
        .map(|m| {
            let h: Header = dynlab_msgs::from_cdr(m.data).unwrap();
            (m.topic.to_string(), m.log_time_ns, h.frame_id)
        })
        .collect();
    let want = [
        ("/b", 5, 3),
        ("/a", 10, 2),
        ("/b", 20, 1),
        ("/a", 20, 4),
        ("/a", 20, 6),
        ("/a", 30, 0),
        ("/b", 40, 5),
    ];
    let want: Vec<(String, u64, String)> = want
        .iter()
        .map(|(t, time, tag)| (t.to_string(), *time, format!("h{tag}")))
        .collect();
    assert_eq!(got, want);
    let a_times: Vec<u64> = bag
        .read::<Header>("/a")
        .unwrap()
        .iter()
        .map(|s| s.log_time_ns)
        .collect();
    assert_eq!(a_times, vec![10, 20, 20, 30]);
}

/// Message counts per chunk and where each chunk ends, from the finished file's summary
/// (chunk indexes and message indexes: the indexed path, not the linear one under test).
fn chunk_ends_and_counts(file: &[u8]) -> Vec<(u64, u64)> {
    let summary = mcap::Summary::read(file)
        .unwrap()
        .expect("finished file has a summary");
    summary
        .chunk_indexes
        .iter()
        .map(|ci| {
            let indexes = summary.read_message_indexes(file, ci).unwrap();
            let n: usize = indexes.values().map(Vec::len).sum();
            (ci.chunk_start_offset + ci.chunk_length, n as u64)
        })
        .collect()
}

#[test]
fn truncation_at_every_stride_recovers_exactly_the_flushed_chunks() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cut");
    let options = WriterOptions {
        chunk_size: 4096,
        ..Default::default()
    };
    let total = write_bag(&dir, 1500, options);
    let full = std::fs::read(mcap_in(&dir)).unwrap();
    let chunks = chunk_ends_and_counts(&full);
    assert!(
        chunks.len() >= 20,
        "want a multi-chunk bag, got {} chunks",
        chunks.len()
    );
    assert_eq!(chunks.iter().map(|c| c.1).sum::<u64>(), total);

    let cut_path = tmp.path().join("cut.mcap");
    let mut previous = 0;
    let mut lengths: Vec<usize> = (0..full.len()).step_by(61).collect();
    lengths.extend([full.len() - 1, full.len()]);
    for len in lengths {
        std::fs::write(&cut_path, &full[..len]).unwrap();
        let expected: u64 = chunks
            .iter()
            .filter(|(end, _)| *end as usize <= len)
            .map(|c| c.1)
            .sum();
        let got = match Bag::open(&cut_path) {
            Ok(bag) => {
                if len < full.len() {
                    let r = bag.recovery().expect("a cut file is reported as damaged");
                    assert_eq!(r.messages, bag.message_count());
                }
                bag.message_count()
            }
            Err(e) => {
                assert!(matches!(e, BagError::Unreadable { .. }), "{e}");
                0
            }
        };
        assert_eq!(got, expected, "prefix of {len} bytes");
        assert!(
            got >= previous,
            "count fell from {previous} to {got} at {len} bytes"
        );
        previous = got;
    }
    assert_eq!(previous, total);
}

#[test]
fn killed_writer_leaves_a_bag_readable_up_to_the_last_flush() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("killed");
    let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    let p = w.add_typed_topic::<PoseStamped>("/car/pose", &[]).unwrap();
    for i in 0..40 {
        w.write(p, T0 + i, &pose(i)).unwrap();
    }
    w.flush().unwrap();
    for i in 40..60 {
        w.write(p, T0 + i, &pose(i)).unwrap();
    }
    // Like SIGKILL: no destructor, no finish; the open chunk is lost.
    std::mem::forget(w);
    let bag = Bag::open(&dir).unwrap();
    assert_eq!(bag.message_count(), 40);
    let r = bag.recovery().expect("unfinished bag is reported");
    assert!(
        r.files[0].reason.contains("without a summary or footer"),
        "{r}"
    );
    assert_eq!(
        bag.read::<PoseStamped>("/car/pose").unwrap()[39].msg,
        pose(39)
    );
    let meta = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
    assert!(meta.contains("\n  message_count: 40\n"), "{meta}");
}

#[test]
fn chunks_close_after_max_chunk_interval_of_log_time() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("interval");
    let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    let p = w.add_typed_topic::<PoseStamped>("/car/pose", &[]).unwrap();
    // 3.5 s at 100 Hz, far below the 1 MiB chunk size: only the interval closes chunks.
    for i in 0..350u64 {
        w.write(p, T0 + i * 10_000_000, &pose(i)).unwrap();
    }
    std::mem::forget(w);
    let bag = Bag::open(&dir).unwrap();
    assert_eq!(
        bag.message_count(),
        300,
        "chunks for [0,1), [1,2), [2,3) s reach the file"
    );
}

#[test]
fn corrupt_chunk_is_skipped_and_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("crc");
    let options = WriterOptions {
        compression: Compression::None,
        chunk_size: 4096,
        ..Default::default()
    };
    let total = write_bag(&dir, 300, options);
    let path = mcap_in(&dir);
    let mut bytes = std::fs::read(&path).unwrap();
    let chunks = chunk_ends_and_counts(&bytes);
    // Flip one byte in the middle of the third chunk's records.
    let (start, end) = (chunks[1].0 as usize, chunks[2].0 as usize);
    bytes[(start + end) / 2] ^= 0x5a;
    std::fs::write(&path, &bytes).unwrap();
    let bag = Bag::open(&dir).unwrap();
    assert_eq!(bag.message_count(), total - chunks[2].1);
    let r = bag.recovery().unwrap();
    assert_eq!(r.files[0].skipped_chunks.len(), 1);
    assert!(r.files[0].skipped_chunks[0].reason.contains("CRC"), "{r}");
    assert!(r.to_string().contains("skipped chunk"));
    let listed = format!(
        "metadata.yaml lists {total} messages, {} were readable",
        bag.message_count()
    );
    assert!(r.notes.iter().any(|n| n.starts_with(&listed)), "{r}");
}

#[test]
fn garbage_tail_keeps_everything_before_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("garbage");
    let options = WriterOptions {
        chunk_size: 4096,
        ..Default::default()
    };
    write_bag(&dir, 600, options);
    let path = mcap_in(&dir);
    let mut bytes = std::fs::read(&path).unwrap();
    let chunks = chunk_ends_and_counts(&bytes);
    let from = chunks[4].0 as usize + 3; // inside the records after the fifth chunk
    let mut state = 0x1234_5678u32;
    for b in &mut bytes[from..] {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        *b = state as u8;
    }
    std::fs::write(&path, &bytes).unwrap();
    let bag = Bag::open(&dir).unwrap();
    assert_eq!(
        bag.message_count(),
        chunks[..5].iter().map(|c| c.1).sum::<u64>()
    );
    assert!(bag.recovery().unwrap().files[0].stopped_at.is_some());
}

#[test]
fn empty_file_empty_dir_and_missing_path_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let empty_file = tmp.path().join("empty.mcap");
    std::fs::write(&empty_file, b"").unwrap();
    let e = Bag::open(&empty_file).unwrap_err().to_string();
    assert!(e.contains("nothing readable") && e.contains("empty"), "{e}");

    let empty_dir = tmp.path().join("emptydir");
    std::fs::create_dir(&empty_dir).unwrap();
    let e = Bag::open(&empty_dir).unwrap_err().to_string();
    assert!(e.contains("without .mcap files"), "{e}");

    let e = Bag::open(tmp.path().join("nope")).unwrap_err().to_string();
    assert!(e.contains("does not exist"), "{e}");

    let not_mcap = tmp.path().join("notes.mcap");
    std::fs::write(&not_mcap, b"hello, this is text").unwrap();
    let e = Bag::open(&not_mcap).unwrap_err().to_string();
    assert!(e.contains("not an MCAP file"), "{e}");
}

#[test]
fn empty_finished_bag_opens_with_no_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("nothing");
    let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    w.add_typed_topic::<Header>("/h", &[]).unwrap();
    w.finish().unwrap();
    let bag = Bag::open(&dir).unwrap();
    assert_eq!(bag.message_count(), 0);
    assert_eq!(bag.topics().len(), 1);
    assert!(bag.read::<Header>("/h").unwrap().is_empty());
    assert_eq!(bag.info().duration_ns, 0);
}

#[test]
fn missing_topic_error_lists_what_the_bag_has() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("foo");
    let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    let p = w.add_typed_topic::<PoseStamped>("/car/pose", &[]).unwrap();
    for i in 0..1200 {
        w.write(p, T0 + i, &pose(i)).unwrap();
    }
    w.finish().unwrap();
    let bag = Bag::open(&dir).unwrap();
    let e = bag.read::<Header>("/car/cmd").unwrap_err().to_string();
    assert!(
        e.starts_with(&format!(
            "topic /car/cmd not in bag {} (has /car/pose [geometry_msgs/msg/PoseStamped, 1200 msgs]); record it",
            dir.display()
        )),
        "{e}"
    );
    assert!(bag.require_topics(&["/car/pose", "/car/cmd"]).is_err());
    assert!(bag.require_topics(&["/car/pose"]).is_ok());
}

#[test]
fn type_mismatch_on_read_and_write() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("types");
    let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    let p = w.add_typed_topic::<PoseStamped>("/car/pose", &[]).unwrap();
    let e = w.write(p, 1, &header(1)).unwrap_err().to_string();
    assert!(
        e.contains("carries geometry_msgs/msg/PoseStamped, not std_msgs/msg/Header"),
        "{e}"
    );
    let e = w
        .add_typed_topic::<Header>("/car/pose", &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("already in this bag as geometry_msgs/msg/PoseStamped"),
        "{e}"
    );
    assert_eq!(
        w.add_typed_topic::<PoseStamped>("/car/pose", &[]).unwrap(),
        p
    );
    w.write(p, 1, &pose(1)).unwrap();
    w.finish().unwrap();
    let bag = Bag::open(&dir).unwrap();
    let e = bag.read::<Header>("/car/pose").unwrap_err();
    assert!(matches!(e, BagError::TypeMismatch { .. }), "{e}");
}

#[test]
fn undecodable_message_names_topic_index_and_time() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("bad_payload");
    let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    let p = w.add_typed_topic::<PoseStamped>("/car/pose", &[]).unwrap();
    w.write(p, 10, &pose(0)).unwrap();
    w.write_raw(p, 20, 20, &[0, 1, 0, 0, 1, 2]).unwrap();
    w.finish().unwrap();
    let e = Bag::open(&dir)
        .unwrap()
        .read::<PoseStamped>("/car/pose")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("message 1 on topic /car/pose (log time 20 ns)"),
        "{e}"
    );
}

#[test]
fn writer_refuses_non_empty_dirs_and_bad_names() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("full");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("x"), b"x").unwrap();
    let e = BagWriter::create(&dir, WriterOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("already exists and is not empty"), "{e}");
    let mut w = BagWriter::create(tmp.path().join("ok"), WriterOptions::default()).unwrap();
    assert!(
        w.add_topic("bad topic", "std_msgs/msg/Header", "", &[])
            .is_err()
    );
    assert!(w.add_topic("/t", "Header", "", &[]).is_err());
}

#[test]
fn bag_dir_without_metadata_and_multi_file_bags_read_in_order() {
    let tmp = tempfile::tempdir().unwrap();
    let mut counts = Vec::new();
    for (k, name) in ["part_a", "part_b"].iter().enumerate() {
        let dir = tmp.path().join(name);
        let mut w = BagWriter::create(&dir, WriterOptions::default()).unwrap();
        let h = w.add_typed_topic::<Header>("/h", &[]).unwrap();
        for i in 0..10u64 {
            w.write(h, (k as u64) * 100 + i, &header(k as u64 * 100 + i))
                .unwrap();
        }
        counts.push(w.finish().unwrap().message_count);
    }
    let multi = tmp.path().join("multi");
    std::fs::create_dir(&multi).unwrap();
    std::fs::copy(
        mcap_in(&tmp.path().join("part_a")),
        multi.join("multi_0.mcap"),
    )
    .unwrap();
    std::fs::copy(
        mcap_in(&tmp.path().join("part_b")),
        multi.join("multi_1.mcap"),
    )
    .unwrap();

    // No metadata.yaml: both files are read, and the bag says so.
    let bag = Bag::open(&multi).unwrap();
    assert_eq!(bag.message_count(), 20);
    assert_eq!(bag.info().files.len(), 2);
    assert!(bag.recovery().unwrap().notes[0].contains("no metadata.yaml"));
    let frames: Vec<String> = bag
        .read::<Header>("/h")
        .unwrap()
        .into_iter()
        .map(|s| s.msg.frame_id)
        .collect();
    assert_eq!(frames.first().map(String::as_str), Some("h0"));
    assert_eq!(frames.last().map(String::as_str), Some("h109"));

    // A metadata.yaml listing only the second file is followed.
    let meta = std::fs::read_to_string(tmp.path().join("part_b/metadata.yaml"))
        .unwrap()
        .replace("part_b_0.mcap", "multi_1.mcap");
    std::fs::write(multi.join("metadata.yaml"), meta).unwrap();
    let bag = Bag::open(&multi).unwrap();
    assert_eq!(bag.message_count(), 10);
    assert!(bag.recovery().is_none());

    // A listed file that is missing is noted; the rest is read.
    let meta = std::fs::read_to_string(multi.join("metadata.yaml"))
        .unwrap()
        .replace(
            "relative_file_paths:\n",
            "relative_file_paths:\n    - multi_9.mcap\n",
        );
    std::fs::write(multi.join("metadata.yaml"), meta).unwrap();
    let bag = Bag::open(&multi).unwrap();
    assert_eq!(bag.message_count(), 10);
    assert!(bag.recovery().unwrap().notes[0].contains("multi_9.mcap"));
}

#[test]
fn random_byte_corruption_never_panics_and_never_invents_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("fuzz");
    let options = WriterOptions {
        chunk_size: 2048,
        ..Default::default()
    };
    let total = write_bag(&dir, 400, options);
    let full = std::fs::read(mcap_in(&dir)).unwrap();
    let path = tmp.path().join("fuzz.mcap");
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut damaged_reads = 0;
    for _ in 0..300 {
        let mut bytes = full.clone();
        // One to four corrupted bytes anywhere, including record lengths and chunk headers.
        for _ in 0..1 + next() % 4 {
            let at = (next() % bytes.len() as u64) as usize;
            bytes[at] = next() as u8;
        }
        std::fs::write(&path, &bytes).unwrap();
        match Bag::open(&path) {
            Ok(bag) => {
                assert!(bag.message_count() <= total);
                if bag.message_count() < total {
                    damaged_reads += 1;
                    assert!(bag.recovery().is_some(), "lost messages without a report");
                }
                // Every recovered payload still decodes or fails with an error, never a panic.
                for t in bag.topics() {
                    if t.type_name == PoseStamped::TYPE_NAME {
                        let _ = bag.read::<PoseStamped>(&t.name);
                    }
                }
            }
            Err(e) => assert!(!e.to_string().is_empty()),
        }
    }
    assert!(
        damaged_reads > 50,
        "corruption should usually cost messages ({damaged_reads})"
    );
}
