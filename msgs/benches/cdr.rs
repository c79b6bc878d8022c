//! CDR encode/decode throughput, with serde_json on the same messages as the peer measured in
//! the same run. Prints a table; run with `cargo bench -p dynlab-msgs`.

use std::hint::black_box;
use std::time::Instant;

use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::geometry_msgs::{Pose, PoseStamped};
use dynlab_msgs::nav_msgs::{Odometry, Path};
use dynlab_msgs::std_msgs::Header;
use dynlab_msgs::{RosMessage, from_cdr, to_cdr};

/// Median time per call in nanoseconds over `rounds` rounds of `iters` calls.
fn time_ns(iters: u32, rounds: usize, mut f: impl FnMut()) -> f64 {
    let mut per_call: Vec<f64> = (0..rounds)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..iters {
                f();
            }
            start.elapsed().as_nanos() as f64 / iters as f64
        })
        .collect();
    per_call.sort_by(f64::total_cmp);
    per_call[rounds / 2]
}

fn row<T: RosMessage>(label: &str, msg: &T, iters: u32) {
    let cdr = to_cdr(msg).unwrap();
    let json = serde_json::to_string(msg).unwrap();
    let enc = time_ns(iters, 9, || {
        black_box(to_cdr(black_box(msg)).unwrap());
    });
    let dec = time_ns(iters, 9, || {
        black_box(from_cdr::<T>(black_box(&cdr)).unwrap());
    });
    let enc_json = time_ns(iters, 9, || {
        black_box(serde_json::to_string(black_box(msg)).unwrap());
    });
    let dec_json = time_ns(iters, 9, || {
        black_box(serde_json::from_str::<T>(black_box(&json)).unwrap());
    });
    println!(
        "| {label:<22} | {:>6} | {enc:>9.0} | {dec:>9.0} | {:>8.1}× | {:>8.1}× |",
        cdr.len(),
        enc_json / enc,
        dec_json / dec
    );
}

fn main() {
    let stamped = PoseStamped {
        header: Header::new(
            Time {
                sec: 1_790_000_000,
                nanosec: 123,
            },
            "world",
        ),
        pose: Pose::planar(0.4, -0.1, 0.6),
    };
    let path = Path {
        header: stamped.header.clone(),
        poses: (0..300)
            .map(|i| PoseStamped {
                pose: Pose::planar(i as f64 * 0.01, 0.0, 0.1),
                ..stamped.clone()
            })
            .collect(),
    };
    println!(
        "| message                | bytes  | encode ns | decode ns | JSON enc / CDR enc | JSON dec / CDR dec |"
    );
    println!("|---|---:|---:|---:|---:|---:|");
    row("PoseStamped", &stamped, 20_000);
    row("Odometry", &Odometry::default(), 20_000);
    row("Path (300 poses)", &path, 200);
}
