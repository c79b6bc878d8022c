//! `dds_probe pub|sub`: publishes `PoseStamped` stamped with the send time, or receives them and
//! reports one-way latency as JSON — the Rust side of the DDS benchmarks (`benches/dds/`).

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use clap::{Parser, Subcommand};
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_nodes::probe::latency_stats;
use dynlab_ros::{Node, NodeArgs, Shutdown, WaitSet, qos};

/// Publishes or receives stamped poses to measure DDS latency and throughput.
#[derive(Parser, Debug)]
#[command(name = "dds_probe")]
struct Cli {
    #[command(subcommand)]
    mode: Mode,
}

#[derive(Subcommand, Debug)]
enum Mode {
    /// Publish `count` poses at `rate` Hz, `header.stamp` = send time, `frame_id` = index.
    Pub {
        /// Topic.
        #[arg(long, default_value = "/probe")]
        topic: String,
        /// Messages per second (0: as fast as possible).
        #[arg(long, default_value_t = 100.0)]
        rate: f64,
        /// Messages to send.
        #[arg(long, default_value_t = 1000)]
        count: u64,
        /// Best-effort (sensor data) instead of reliable QoS.
        #[arg(long)]
        best_effort: bool,
        /// Wait up to this many seconds for a subscriber before sending.
        #[arg(long, default_value_t = 10.0)]
        wait: f64,
    },
    /// Receive up to `count` poses and print latency statistics as one JSON line.
    Sub {
        /// Topic.
        #[arg(long, default_value = "/probe")]
        topic: String,
        /// Messages to wait for.
        #[arg(long, default_value_t = 1000)]
        count: u64,
        /// Give up after this many seconds without a message (after the first).
        #[arg(long, default_value_t = 3.0)]
        idle_timeout: f64,
        /// Best-effort (sensor data) instead of reliable QoS.
        #[arg(long)]
        best_effort: bool,
        /// Ignore this many first messages (warm-up) in the statistics.
        #[arg(long, default_value_t = 0)]
        skip: u64,
    },
}

fn now_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}

fn main() -> anyhow::Result<()> {
    let args = NodeArgs::from_env()?;
    let cli = Cli::parse_from(
        std::iter::once("dds_probe".to_owned()).chain(args.program_args.iter().cloned()),
    );
    dynlab_ros::init_logging(args.log_level);
    let shutdown = Shutdown::install()?;
    let mut node = Node::new("dds_probe", &args)?;
    let profile = |best_effort: bool| {
        if best_effort {
            qos::sensor_data()
        } else {
            qos::default_profile()
        }
    };
    match cli.mode {
        Mode::Pub {
            topic,
            rate,
            count,
            best_effort,
            wait,
        } => {
            let publisher = node.create_publisher::<PoseStamped>(&topic, profile(best_effort))?;
            let deadline = Instant::now() + Duration::from_secs_f64(wait);
            while publisher.subscription_count() == 0
                && Instant::now() < deadline
                && !shutdown.requested()
            {
                std::thread::sleep(Duration::from_millis(10));
            }
            std::thread::sleep(Duration::from_millis(300));
            let period = if rate > 0.0 {
                Duration::from_secs_f64(1.0 / rate)
            } else {
                Duration::ZERO
            };
            let start = Instant::now();
            let mut msg = PoseStamped::default();
            for i in 0..count {
                if shutdown.requested() {
                    break;
                }
                let due = start + period * i as u32;
                let now = Instant::now();
                if due > now {
                    std::thread::sleep(due - now);
                }
                msg.header.frame_id = i.to_string();
                msg.pose.position.x = i as f64;
                msg.header.stamp = Time::from_nanos(now_ns());
                publisher.publish(msg.clone())?;
            }
            let elapsed = start.elapsed().as_secs_f64();
            println!("{{\"sent\": {count}, \"seconds\": {elapsed:.6}}}");
            std::thread::sleep(Duration::from_millis(500));
        }
        Mode::Sub {
            topic,
            count,
            idle_timeout,
            best_effort,
            skip,
        } => {
            let mut sub = node.create_subscription::<PoseStamped>(&topic, profile(best_effort))?;
            let mut waits = WaitSet::new()?;
            waits.add(&mut sub)?;
            println!("{{\"ready\": true}}");
            let mut latencies = Vec::with_capacity(count as usize);
            let mut received = 0u64;
            let mut last = Instant::now();
            let mut first: Option<Instant> = None;
            let idle = Duration::from_secs_f64(idle_timeout);
            while received < count && !shutdown.requested() {
                waits.wait(Duration::from_millis(50))?;
                while let Some(msg) = sub.take()? {
                    let t = now_ns();
                    received += 1;
                    if received > skip {
                        latencies.push(t - msg.header.stamp.to_nanos());
                    }
                    last = Instant::now();
                    first.get_or_insert(last);
                }
                if first.is_some() && last.elapsed() > idle {
                    break;
                }
            }
            let span = first
                .map(|f| last.duration_since(f).as_secs_f64())
                .unwrap_or(0.0);
            match latency_stats(&latencies) {
                Some(s) => println!(
                    "{{\"received\": {received}, \"seconds\": {span:.6}, \"p50_us\": {:.1}, \"p99_us\": {:.1}, \"max_us\": {:.1}, \"mean_us\": {:.1}}}",
                    s.p50_us, s.p99_us, s.max_us, s.mean_us
                ),
                None => println!("{{\"received\": {received}, \"seconds\": {span:.6}}}"),
            }
        }
    }
    Ok(())
}
