//! `recorder -o DIR [TOPIC…] [--all] [--ros-args …]`: records topics into a rosbag2-compatible
//! bag directory, flushing at least every second; SIGINT/SIGTERM finish the bag.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use dynlab_bag::{Compression, WriterOptions};
use dynlab_nodes::record::{RecordOptions, Recorder, plan_topic, wants_topic};
use dynlab_ros::{Node, NodeArgs, QosProfile, RawSubscription, Shutdown, WaitSet};

/// Records ROS 2 topics into a bag directory exactly as rosbag2 (Jazzy) writes it.
#[derive(Parser, Debug)]
#[command(
    name = "recorder",
    after_help = "ROS arguments go after --ros-args, e.g. --ros-args -r /car/pose:=/mocap/pose"
)]
struct Cli {
    /// Bag directory to create (must not exist or be empty).
    #[arg(short = 'o', long)]
    output: PathBuf,
    /// Topics to record (relative names are resolved in the node's namespace; remaps apply).
    topics: Vec<String>,
    /// Record every topic discovered, as it appears.
    #[arg(short = 'a', long)]
    all: bool,
    /// Longest time between flushes to disk (s); a killed recorder loses at most this much.
    #[arg(long, default_value_t = 1.0)]
    flush_period: f64,
    /// Chunk compression: zstd or none.
    #[arg(long, default_value = "zstd")]
    compression: String,
}

/// How often the discovery database is scanned for new publishers.
const SCAN_PERIOD: Duration = Duration::from_millis(200);
/// Longest wait between checks of the shutdown flag.
const MAX_WAIT: Duration = Duration::from_millis(100);

struct Recorded {
    topic: String,
    sub: RawSubscription,
}

fn main() -> anyhow::Result<()> {
    let args = NodeArgs::from_env()?;
    let cli = Cli::parse_from(
        std::iter::once("recorder".to_owned()).chain(args.program_args.iter().cloned()),
    );
    dynlab_ros::init_logging(args.log_level);
    let shutdown = Shutdown::install()?;
    let mut node = Node::new("recorder", &args)?;
    let clock = node.clock()?;

    let mut options = RecordOptions::new(&cli.output);
    options.all = cli.all;
    options.topics = cli
        .topics
        .iter()
        .map(|t| node.resolve_topic(t))
        .collect::<Result<_, _>>()?;
    anyhow::ensure!(
        cli.flush_period.is_finite() && cli.flush_period > 0.0,
        "--flush-period {} must be a positive number of seconds",
        cli.flush_period
    );
    options.flush_period_ns = (cli.flush_period * 1e9) as i64;
    options.writer = WriterOptions {
        compression: match cli.compression.as_str() {
            "zstd" => Compression::Zstd,
            "none" => Compression::None,
            other => anyhow::bail!("--compression {other}: use zstd or none"),
        },
        // Chunks close on the flush period too (in log time), so a slow topic still reaches disk.
        max_chunk_interval_ns: options.flush_period_ns.max(1) as u64,
        ..WriterOptions::default()
    };

    let start = Instant::now();
    let mono = || start.elapsed().as_nanos() as i64;
    let mut recorder = Recorder::create(&options, mono())
        .with_context(|| format!("creating {}", cli.output.display()))?;
    tracing::info!(
        node = %node.fully_qualified_name(),
        domain = node.domain_id(),
        bag = %cli.output.display(),
        "recording {}",
        if options.all { "all topics".to_owned() } else { options.topics.join(" ") }
    );

    let mut waits = WaitSet::new()?;
    let mut recorded: Vec<Recorded> = Vec::new();
    let mut subscribed: BTreeSet<String> = BTreeSet::new();
    let mut next_scan = 0i64;
    while !shutdown.requested() {
        if mono() >= next_scan {
            // Group publishers by topic: one subscription per topic, QoS adapted to all offers.
            let mut offers: BTreeMap<String, (String, Vec<QosProfile>)> = BTreeMap::new();
            for p in node.discovered_publications() {
                if subscribed.contains(&p.topic) || !wants_topic(&options, &p.topic) {
                    continue;
                }
                offers
                    .entry(p.topic.clone())
                    .or_insert_with(|| (p.dds_type.clone(), Vec::new()))
                    .1
                    .push(p.qos);
            }
            for (topic, (dds_type, qos)) in offers {
                let plan = match plan_topic(&topic, &dds_type, &qos) {
                    Ok(plan) => plan,
                    Err(e) => {
                        tracing::warn!("skipping {topic}: {e}");
                        subscribed.insert(topic);
                        continue;
                    }
                };
                if !plan.known_type {
                    tracing::warn!(
                        "{topic}: type {} is not in dynlab_msgs; recording it without a definition \
                         (ros2 bag play works, tools that decode need the definition)",
                        plan.type_name
                    );
                }
                recorder.add_topic(&plan)?;
                let mut sub = node.create_raw_subscription_exact(
                    &topic,
                    &dds_type,
                    plan.subscription_qos.clone(),
                )?;
                waits.add(&mut sub)?;
                tracing::info!("subscribed to {topic} [{}]", plan.type_name);
                subscribed.insert(topic.clone());
                recorded.push(Recorded { topic, sub });
            }
            next_scan = mono() + SCAN_PERIOD.as_nanos() as i64;
        }
        let until_flush = Duration::from_nanos(recorder.until_flush_ns(mono()) as u64);
        waits.wait(MAX_WAIT.min(until_flush).max(Duration::from_millis(1)))?;
        drain(&recorded, &mut recorder, &clock)?;
        recorder.maybe_flush(mono())?;
    }
    drain(&recorded, &mut recorder, &clock)?;
    for t in &options.topics {
        if !subscribed.contains(t) {
            tracing::warn!("no publisher of {t} was seen; it is not in the bag");
        }
    }
    let summary = recorder.finish()?;
    eprintln!(
        "recorder: wrote {} messages on {} topics to {}",
        summary.message_count,
        summary.topics.len(),
        summary.dir.display()
    );
    for (name, ty, count) in &summary.topics {
        eprintln!("  {name} [{ty}]: {count}");
    }
    Ok(())
}

/// Writes every waiting message. Log time is the receive time, or sim time with `use_sim_time`.
fn drain(
    recorded: &[Recorded],
    recorder: &mut Recorder,
    clock: &dynlab_ros::Clock,
) -> anyhow::Result<()> {
    for r in recorded {
        while let Some(m) = r.sub.take()? {
            let log_time = if clock.is_sim() {
                clock.now_ns()?
            } else {
                m.received_ns
            };
            recorder.write(
                &r.topic,
                log_time,
                m.source_ns.unwrap_or(m.received_ns),
                &m.msg.data,
            )?;
        }
    }
    Ok(())
}
