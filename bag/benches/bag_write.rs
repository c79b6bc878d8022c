//! Writing and reading PoseStamped bags: messages/s and MB/s with zstd and without, beside the
//! Python `mcap` writer and reader (the reference implementation's Python package) handling the
//! same payloads in the same run, when the repository's `.venv` is present.
//!
//! Run: `cargo bench -p dynlab-bag --bench bag_write` (set `BAG_BENCH_N` to change the message
//! count, default 200000).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use dynlab_bag::{Bag, BagWriter, Compression, QosProfile, WriterOptions};
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::geometry_msgs::PoseStamped;

const T0: u64 = 1_700_000_000_000_000_000;

fn poses(n: usize) -> Vec<PoseStamped> {
    (0..n)
        .map(|i| {
            let mut p = PoseStamped::default();
            p.header.stamp = Time::from_nanos((T0 + i as u64 * 4_166_667) as i64);
            p.header.frame_id = "world".into();
            let t = i as f64 * 0.004;
            p.pose.position.x = t.cos() * 2.0;
            p.pose.position.y = (2.0 * t).sin();
            p.pose.orientation.z = (t * 0.5).sin();
            p.pose.orientation.w = (t * 0.5).cos();
            p
        })
        .collect()
}

struct Row {
    case: String,
    seconds: f64,
    messages: usize,
    payload_bytes: usize,
    file_bytes: u64,
}

fn write_bag(dir: &Path, msgs: &[PoseStamped], compression: Compression) -> (f64, u64) {
    let _ = std::fs::remove_dir_all(dir);
    let start = Instant::now();
    let mut w = BagWriter::create(
        dir,
        WriterOptions {
            compression,
            ..Default::default()
        },
    )
    .expect("create bag");
    let topic = w
        .add_typed_topic::<PoseStamped>("/car/pose", &[QosProfile::sensor_data()])
        .expect("topic");
    for (i, m) in msgs.iter().enumerate() {
        w.write(topic, T0 + i as u64 * 4_166_667, m).expect("write");
    }
    let summary = w.finish().expect("finish");
    (start.elapsed().as_secs_f64(), summary.file_bytes)
}

fn read_bag(dir: &Path, n: usize) -> f64 {
    let start = Instant::now();
    let bag = Bag::open(dir).expect("open");
    let got = bag.read::<PoseStamped>("/car/pose").expect("read");
    assert_eq!(got.len(), n);
    start.elapsed().as_secs_f64()
}

const PYTHON_PEER: &str = r#"
import struct, sys, time
from mcap.writer import Writer, CompressionType
from mcap.reader import make_reader
payloads = []
with open(sys.argv[1], "rb") as f:
    data = f.read()
pos = 0
while pos < len(data):
    (n,) = struct.unpack_from("<I", data, pos)
    payloads.append(data[pos + 4 : pos + 4 + n])
    pos += 4 + n
for name, comp in (("zstd", CompressionType.ZSTD), ("none", CompressionType.NONE)):
    out = sys.argv[2] + "_" + name + ".mcap"
    t = time.perf_counter()
    with open(out, "wb") as f:
        w = Writer(f, compression=comp, chunk_size=1024 * 1024)
        w.start(profile="ros2", library="bench")
        s = w.register_schema("geometry_msgs/msg/PoseStamped", "ros2msg", b"")
        c = w.register_channel("/car/pose", "cdr", s)
        t0 = 1_700_000_000_000_000_000
        for i, p in enumerate(payloads):
            w.add_message(c, t0 + i * 4_166_667, p, t0 + i * 4_166_667, i)
        w.finish()
    wrote = time.perf_counter() - t
    t = time.perf_counter()
    with open(out, "rb") as f:
        count = sum(1 for _ in make_reader(f).iter_messages())
    read = time.perf_counter() - t
    assert count == len(payloads)
    print(name, wrote, read)
"#;

fn python_peer(repo: &Path, tmp: &Path, msgs: &[PoseStamped]) -> Option<Vec<(String, f64, f64)>> {
    let python = repo.join(".venv/bin/python");
    if !python.exists() {
        return None;
    }
    let payload_file = tmp.join("payloads.bin");
    let mut f = std::io::BufWriter::new(std::fs::File::create(&payload_file).ok()?);
    for m in msgs {
        let cdr = dynlab_msgs::to_cdr(m).ok()?;
        f.write_all(&(cdr.len() as u32).to_le_bytes()).ok()?;
        f.write_all(&cdr).ok()?;
    }
    f.flush().ok()?;
    drop(f);
    let out = Command::new(python)
        .arg("-c")
        .arg(PYTHON_PEER)
        .arg(&payload_file)
        .arg(tmp.join("py"))
        .output()
        .ok()?;
    if !out.status.success() {
        eprintln!(
            "python peer failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        return None;
    }
    String::from_utf8(out.stdout)
        .ok()?
        .lines()
        .map(|l| {
            let mut parts = l.split_whitespace();
            Some((
                parts.next()?.to_string(),
                parts.next()?.parse().ok()?,
                parts.next()?.parse().ok()?,
            ))
        })
        .collect()
}

fn main() {
    let n: usize = std::env::var("BAG_BENCH_N")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200_000);
    let msgs = poses(n);
    let payload: usize = msgs
        .iter()
        .map(|m| dynlab_msgs::to_cdr(m).map(|c| c.len()).unwrap_or(0))
        .sum();
    let tmp = tempfile::tempdir().expect("tempdir");
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");

    let mut rows = Vec::new();
    for (name, compression) in [("zstd", Compression::Zstd), ("none", Compression::None)] {
        let dir = tmp.path().join(format!("bench_{name}"));
        let (secs, bytes) = write_bag(&dir, &msgs, compression);
        rows.push(Row {
            case: format!("dynlab write {name}"),
            seconds: secs,
            messages: n,
            payload_bytes: payload,
            file_bytes: bytes,
        });
        let secs = read_bag(&dir, n);
        rows.push(Row {
            case: format!("dynlab read  {name}"),
            seconds: secs,
            messages: n,
            payload_bytes: payload,
            file_bytes: bytes,
        });
    }
    let peer = python_peer(&repo, tmp.path(), &msgs);
    if let Some(peer) = &peer {
        for (name, wrote, read) in peer {
            let bytes = std::fs::metadata(tmp.path().join(format!("py_{name}.mcap")))
                .map(|m| m.len())
                .unwrap_or(0);
            rows.push(Row {
                case: format!("python mcap write {name}"),
                seconds: *wrote,
                messages: n,
                payload_bytes: payload,
                file_bytes: bytes,
            });
            rows.push(Row {
                case: format!("python mcap read  {name}"),
                seconds: *read,
                messages: n,
                payload_bytes: payload,
                file_bytes: bytes,
            });
        }
    }

    println!(
        "{n} PoseStamped messages, {:.1} MB of CDR payload",
        payload as f64 / 1e6
    );
    println!(
        "{:<24} {:>10} {:>12} {:>10} {:>12} {:>14}",
        "case", "seconds", "msgs/s", "MB/s", "file MB", "vs python"
    );
    for r in &rows {
        let peer_secs = rows
            .iter()
            .find(|p| {
                p.case.starts_with("python")
                    && p.case
                        .ends_with(r.case.split_whitespace().last().unwrap_or(""))
                    && p.case
                        .contains(r.case.split_whitespace().nth(1).unwrap_or(""))
            })
            .map(|p| p.seconds);
        let ratio = match (r.case.starts_with("dynlab"), peer_secs) {
            (true, Some(p)) => format!("{:.1}x faster", p / r.seconds),
            _ => "-".to_string(),
        };
        println!(
            "{:<24} {:>10.3} {:>12.0} {:>10.1} {:>12.2} {:>14}",
            r.case,
            r.seconds,
            r.messages as f64 / r.seconds,
            r.payload_bytes as f64 / 1e6 / r.seconds,
            r.file_bytes as f64 / 1e6,
            ratio
        );
    }
    if peer.is_none() {
        println!(
            "(python peer skipped: no .venv with the `mcap` package; run tests/setup_python.sh)"
        );
    }
}
