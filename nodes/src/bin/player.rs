//! `player BAG [--rate R] [--loop] [--clock-rate HZ] [--topics …] [--ros-args -r …]`: publishes a
//! bag's messages unchanged with their recorded timing, type and QoS, and `/clock` from bag time.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use dynlab_bag::Bag;
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::rosgraph_msgs::Clock as ClockMsg;
use dynlab_nodes::play::{PassEnd, PlayMessage, PlayOptions, PlaySink, Timer, play_pass};
use dynlab_nodes::record::playback_qos;
use dynlab_ros::{Node, NodeArgs, Publisher, RawPublisher, Shutdown, qos};

/// Plays a bag directory or a bare `.mcap` file onto ROS 2 topics.
#[derive(Parser, Debug)]
#[command(
    name = "player",
    after_help = "Remap topics after --ros-args, e.g. --ros-args -r /car/pose:=/sim/pose"
)]
struct Cli {
    /// Bag directory (with metadata.yaml) or .mcap file.
    bag: PathBuf,
    /// Playback speed factor.
    #[arg(short, long, default_value_t = 1.0)]
    rate: f64,
    /// Play again from the start when the end is reached, until interrupted.
    #[arg(short = 'l', long = "loop")]
    loop_playback: bool,
    /// /clock rate in Hz of wall time; 0 publishes no /clock.
    #[arg(long, default_value_t = 100.0)]
    clock_rate: f64,
    /// Only these topics (bag names, before remapping).
    #[arg(long, num_args = 1..)]
    topics: Vec<String>,
    /// Before playing, wait up to this many seconds for every topic to have a subscriber.
    #[arg(long, default_value_t = 0.0)]
    wait_for_subscribers: f64,
}

struct WallTimer {
    start: Instant,
}

impl Timer for WallTimer {
    fn now_ns(&mut self) -> i64 {
        self.start.elapsed().as_nanos() as i64
    }
    fn sleep_until(&mut self, deadline_ns: i64) {
        let now = self.now_ns();
        if deadline_ns > now {
            std::thread::sleep(Duration::from_nanos((deadline_ns - now) as u64));
        }
    }
}

struct DdsSink {
    publishers: Vec<RawPublisher>,
    clock: Option<Publisher<ClockMsg>>,
}

impl PlaySink for DdsSink {
    fn publish(&mut self, topic_index: usize, data: &[u8]) -> Result<(), String> {
        let p = self
            .publishers
            .get(topic_index)
            .ok_or_else(|| format!("no publisher for topic #{topic_index}"))?;
        p.publish(data).map_err(|e| e.to_string())
    }
    fn clock(&mut self, bag_time_ns: i64) -> Result<(), String> {
        match &self.clock {
            Some(c) => c
                .publish(ClockMsg {
                    clock: Time::from_nanos(bag_time_ns),
                })
                .map_err(|e| e.to_string()),
            None => Ok(()),
        }
    }
}

fn main() -> anyhow::Result<()> {
    let args = NodeArgs::from_env()?;
    let cli = Cli::parse_from(
        std::iter::once("player".to_owned()).chain(args.program_args.iter().cloned()),
    );
    dynlab_ros::init_logging(args.log_level);
    let shutdown = Shutdown::install()?;
    let options = PlayOptions {
        rate: cli.rate,
        loop_playback: cli.loop_playback,
        clock_hz: (cli.clock_rate != 0.0).then_some(cli.clock_rate),
        topics: cli.topics.clone(),
    };
    options.validate()?;
    let bag = Bag::open(&cli.bag).with_context(|| format!("opening {}", cli.bag.display()))?;
    if let Some(r) = bag.recovery() {
        tracing::warn!("{}: {r}", cli.bag.display());
    }
    let bag_topics: Vec<String> = bag.topics().iter().map(|t| t.name.clone()).collect();
    let selected: Vec<String> = options
        .select_topics(&bag_topics)?
        .into_iter()
        .cloned()
        .collect();

    let mut node = Node::new("player", &args)?;
    let mut publishers = Vec::new();
    for name in &selected {
        let info = bag.topic(name).context("topic vanished from the bag")?;
        let p = node.create_raw_publisher(name, &info.type_name, playback_qos(&info.qos))?;
        tracing::info!(
            "{name} [{}] → {} ({} messages)",
            info.type_name,
            p.topic(),
            info.count
        );
        publishers.push(p);
    }
    let clock = match options.clock_hz {
        Some(_) => Some(node.create_publisher::<ClockMsg>("/clock", qos::clock())?),
        None => None,
    };

    if cli.wait_for_subscribers > 0.0 {
        let deadline = Instant::now() + Duration::from_secs_f64(cli.wait_for_subscribers);
        while !shutdown.requested()
            && Instant::now() < deadline
            && publishers.iter().any(|p| p.subscription_count() == 0)
        {
            std::thread::sleep(Duration::from_millis(20));
        }
        for p in publishers.iter().filter(|p| p.subscription_count() == 0) {
            tracing::warn!(
                "no subscriber on {} after {} s; playing anyway",
                p.topic(),
                cli.wait_for_subscribers
            );
        }
        // Discovery has seen the readers; give the reliable handshake a moment to complete.
        std::thread::sleep(Duration::from_millis(300));
    }

    let index_of = |topic: &str| selected.iter().position(|t| t == topic);
    let bag_start = bag
        .messages()
        .find(|m| index_of(m.topic).is_some())
        .map(|m| m.log_time_ns as i64)
        .unwrap_or(0);
    let mut sink = DdsSink { publishers, clock };
    let mut timer = WallTimer {
        start: Instant::now(),
    };
    let stop = || shutdown.requested();
    let mut total = 0u64;
    loop {
        let messages = bag.messages().filter_map(|m| {
            index_of(m.topic).map(|i| {
                Ok(PlayMessage {
                    topic_index: i,
                    log_time_ns: m.log_time_ns as i64,
                    data: m.data.to_vec(),
                })
            })
        });
        match play_pass(&options, bag_start, messages, &mut sink, &mut timer, &stop)? {
            PassEnd::Completed { published } => total += published,
            PassEnd::Interrupted { published } => {
                total += published;
                break;
            }
        }
        if !options.loop_playback || shutdown.requested() {
            break;
        }
    }
    for p in &sink.publishers {
        if !p.wait_for_acknowledgments(Duration::from_secs(2)) {
            tracing::debug!(
                "{}: not every subscriber acknowledged the last messages",
                p.topic()
            );
        }
    }
    eprintln!("player: published {total} messages");
    Ok(())
}
