//! `dynlab bag info | export | import | repair`: look into bags, convert them to and from JSON
//! lines, and rewrite damaged ones.
//!
//! The JSON-lines form has one message per line:
//! `{"topic": "/car/pose", "type": "geometry_msgs/msg/PoseStamped", "log_time_ns": …,
//! "publish_time_ns": …, "value": {…}}`, where `value` is the message's JSON form from the
//! `dynlab-msgs` registry (ROS field names; non-finite floats as `"NaN"`, `"Infinity"`,
//! `"-Infinity"`). Messages of types the registry does not know are exported with
//! `"value": null` and their CDR bytes in `"cdr_hex"`.

use std::collections::{BTreeSet, HashMap};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::PathBuf;

use anyhow::{Context, anyhow, bail};
use clap::{Args, Subcommand, ValueEnum};
use dynlab_bag::{Bag, BagWriter, Compression, QosProfile, RawMessage, TopicId, WriterOptions};
use serde_json::Value;

/// `dynlab bag …`
#[derive(Debug, Args)]
pub struct BagArgs {
    #[command(subcommand)]
    command: BagCommand,
}

#[derive(Debug, Subcommand)]
enum BagCommand {
    /// Topics, types, counts, rates, first and last stamps, duration, files; what was recovered
    /// from a damaged bag.
    Info {
        /// A bag directory (with or without metadata.yaml) or an .mcap file.
        bag: PathBuf,
    },
    /// Writes every message as one JSON line, ordered by log time.
    Export {
        /// A bag directory or an .mcap file.
        bag: PathBuf,
        /// Export only this topic (repeatable); default: all topics.
        #[arg(long = "topic", value_name = "TOPIC")]
        topics: Vec<String>,
        /// Write to this file instead of standard output.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
    },
    /// Lists the message types export and import understand, one JSON line each:
    /// `{"type": …, "definition": …}` (the full ros2msg schema text written into bags).
    Types,
    /// Builds a bag from JSON lines (the export format; `publish_time_ns` is optional).
    Import {
        /// The JSON-lines file (`-` for standard input).
        jsonl: PathBuf,
        /// The bag directory to create (must not exist or be empty).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Chunk compression.
        #[arg(long, value_enum, default_value_t = CompressionArg::Zstd)]
        compression: CompressionArg,
        /// Uncompressed bytes per chunk.
        #[arg(long, default_value_t = WriterOptions::default().chunk_size)]
        chunk_size: u64,
        /// The QoS profile recorded for every topic.
        #[arg(long, value_enum, default_value_t = QosArg::Default)]
        qos: QosArg,
    },
    /// Rewrites a damaged or truncated bag whole: everything the recovering reader can read,
    /// into a fresh, valid bag (MCAP with summary + metadata.yaml); prints what was kept and
    /// dropped.
    Repair {
        /// The damaged bag (a directory or an .mcap file).
        input: PathBuf,
        /// The bag directory to create (must not exist or be empty).
        output: PathBuf,
        /// Also drop messages with NaN or infinite fields (an occluded motion-capture body).
        #[arg(long)]
        drop_nonfinite: bool,
        /// Chunk compression of the new bag.
        #[arg(long, value_enum, default_value_t = CompressionArg::Zstd)]
        compression: CompressionArg,
    },
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum CompressionArg {
    Zstd,
    None,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum QosArg {
    /// Reliable, keep last 10, volatile.
    Default,
    /// Best effort, keep last 5, volatile.
    SensorData,
}

/// Runs a `dynlab bag` command.
pub fn run(args: BagArgs) -> anyhow::Result<()> {
    match args.command {
        BagCommand::Info { bag } => info(bag),
        BagCommand::Types => {
            for t in dynlab_msgs::all() {
                let line = serde_json::json!({"type": t.type_name, "definition": t.definition});
                println!("{line}");
            }
            Ok(())
        }
        BagCommand::Export { bag, topics, out } => export(bag, &topics, out),
        BagCommand::Import {
            jsonl,
            out,
            compression,
            chunk_size,
            qos,
        } => import(jsonl, out, compression, chunk_size, qos),
        BagCommand::Repair {
            input,
            output,
            drop_nonfinite,
            compression,
        } => {
            let options = dynlab_bag::RepairOptions {
                drop_nonfinite,
                writer: WriterOptions {
                    compression: match compression {
                        CompressionArg::Zstd => Compression::Zstd,
                        CompressionArg::None => Compression::None,
                    },
                    ..WriterOptions::default()
                },
            };
            let report = dynlab_bag::repair(&input, &output, &options)
                .with_context(|| format!("repairing {}", input.display()))?;
            print!("{report}");
            Ok(())
        }
    }
}

fn info(path: PathBuf) -> anyhow::Result<()> {
    let bag = Bag::open(&path)?;
    print!("{}", bag.info());
    Ok(())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// One export line, with the keys in the documented order.
fn json_line(m: &RawMessage<'_>, value: &Value, cdr_hex: Option<&str>) -> String {
    let text = |s: &str| Value::String(s.to_string()).to_string();
    let mut line = format!(
        "{{\"topic\":{},\"type\":{},\"log_time_ns\":{},\"publish_time_ns\":{},\"value\":{}",
        text(m.topic),
        text(m.type_name),
        m.log_time_ns,
        m.publish_time_ns,
        value
    );
    if let Some(h) = cdr_hex {
        line.push_str(&format!(",\"cdr_hex\":{}", text(h)));
    }
    line.push('}');
    line
}

fn export(path: PathBuf, topics: &[String], out: Option<PathBuf>) -> anyhow::Result<()> {
    let bag = Bag::open(&path)?;
    let wanted: Vec<&str> = topics.iter().map(String::as_str).collect();
    bag.require_topics(&wanted)?;
    if let Some(r) = bag.recovery() {
        eprint!("warning: {r}");
    }
    let sink: Box<dyn Write> = match &out {
        Some(file) => {
            Box::new(File::create(file).with_context(|| format!("creating {}", file.display()))?)
        }
        None => Box::new(std::io::stdout().lock()),
    };
    let mut sink = BufWriter::new(sink);
    let mut unknown_types = BTreeSet::new();
    let mut per_topic: HashMap<&str, usize> = HashMap::new();
    for m in bag.messages() {
        if !wanted.is_empty() && !wanted.contains(&m.topic) {
            continue;
        }
        let index = per_topic.entry(m.topic).or_default();
        let line = match dynlab_msgs::lookup(m.type_name) {
            Some(t) => {
                let value = (t.to_json)(m.data).map_err(|e| {
                    anyhow!(
                        "message {index} on topic {} (log time {} ns) does not decode as {}: {e}",
                        m.topic,
                        m.log_time_ns,
                        m.type_name
                    )
                })?;
                json_line(&m, &value, None)
            }
            None => {
                if unknown_types.insert(m.type_name.to_string()) {
                    eprintln!(
                        "warning: type {} (topic {}) is not in the message registry; exporting \
                         its CDR bytes as cdr_hex",
                        m.type_name, m.topic
                    );
                }
                json_line(&m, &Value::Null, Some(&hex(m.data)))
            }
        };
        *index += 1;
        if let Err(e) = writeln!(sink, "{line}") {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                return Ok(()); // e.g. `dynlab bag export … | head`
            }
            return Err(e).context("writing JSON lines");
        }
    }
    match sink.flush() {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(e).context("writing JSON lines")
        }
        _ => Ok(()),
    }
}

/// The fields of one JSON line.
struct Line {
    topic: String,
    type_name: String,
    log_time_ns: u64,
    publish_time_ns: u64,
    value: Value,
}

fn parse_line(text: &str) -> anyhow::Result<Line> {
    let v: Value = serde_json::from_str(text).context("not JSON")?;
    let obj = v.as_object().ok_or_else(|| anyhow!("not a JSON object"))?;
    let string = |key: &str| -> anyhow::Result<String> {
        obj.get(key)
            .and_then(Value::as_str)
            .map(str::to_string)
            .ok_or_else(|| anyhow!("no string field \"{key}\""))
    };
    let time = |key: &str| -> anyhow::Result<Option<u64>> {
        match obj.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(t) => t
                .as_u64()
                .map(Some)
                .ok_or_else(|| anyhow!("\"{key}\" must be a non-negative integer (nanoseconds)")),
        }
    };
    let log_time_ns = time("log_time_ns")?.ok_or_else(|| anyhow!("no field \"log_time_ns\""))?;
    if obj.get("value").is_none_or(Value::is_null) {
        bail!("no \"value\" (lines with only cdr_hex cannot be imported: their schema is unknown)");
    }
    Ok(Line {
        topic: string("topic")?,
        type_name: string("type")?,
        log_time_ns,
        publish_time_ns: time("publish_time_ns")?.unwrap_or(log_time_ns),
        value: obj["value"].clone(),
    })
}

fn import(
    jsonl: PathBuf,
    out: PathBuf,
    compression: CompressionArg,
    chunk_size: u64,
    qos: QosArg,
) -> anyhow::Result<()> {
    let reader: Box<dyn BufRead> = if jsonl.as_os_str() == "-" {
        Box::new(BufReader::new(std::io::stdin().lock()))
    } else {
        Box::new(BufReader::new(
            File::open(&jsonl).with_context(|| format!("opening {}", jsonl.display()))?,
        ))
    };
    let options = WriterOptions {
        compression: match compression {
            CompressionArg::Zstd => Compression::Zstd,
            CompressionArg::None => Compression::None,
        },
        chunk_size,
        ..WriterOptions::default()
    };
    let qos = match qos {
        QosArg::Default => QosProfile::default_profile(),
        QosArg::SensorData => QosProfile::sensor_data(),
    };
    let existed = out.exists();
    let mut writer = BagWriter::create(&out, options)?;
    let result = import_lines(reader, &jsonl, &mut writer, qos);
    let count = match result {
        Ok(count) => count,
        Err(e) => {
            // Leave no half-made bag behind: the directory was empty or new.
            drop(writer);
            let _ = std::fs::remove_dir_all(&out);
            if existed {
                let _ = std::fs::create_dir(&out);
            }
            return Err(e);
        }
    };
    let summary = writer.finish()?;
    eprintln!(
        "wrote {count} messages on {} topics to {} ({} bytes)",
        summary.topics.len(),
        summary.dir.display(),
        summary.file_bytes
    );
    Ok(())
}

/// Writes every line of `reader` into `writer`; returns the number of messages.
fn import_lines(
    reader: Box<dyn BufRead>,
    jsonl: &std::path::Path,
    writer: &mut BagWriter,
    qos: QosProfile,
) -> anyhow::Result<u64> {
    let mut topics: HashMap<String, TopicId> = HashMap::new();
    let mut count = 0u64;
    for (n, line) in reader.lines().enumerate() {
        let lineno = n + 1;
        let text = line.with_context(|| format!("reading {} line {lineno}", jsonl.display()))?;
        if text.trim().is_empty() {
            continue;
        }
        let at = || format!("{} line {lineno}", jsonl.display());
        let line = parse_line(&text).with_context(at)?;
        let t = dynlab_msgs::lookup(&line.type_name).ok_or_else(|| {
            let known: Vec<&str> = dynlab_msgs::all().iter().map(|t| t.type_name).collect();
            anyhow!(
                "{}: type {} is not in the message registry (known: {})",
                at(),
                line.type_name,
                known.join(", ")
            )
        })?;
        let cdr = (t.from_json)(&line.value).with_context(at)?;
        let id = match topics.get(&line.topic) {
            Some(id) => *id,
            None => {
                let id = writer
                    .add_topic(&line.topic, t.type_name, t.definition, &[qos])
                    .with_context(at)?;
                topics.insert(line.topic.clone(), id);
                id
            }
        };
        writer
            .write_raw(id, line.log_time_ns, line.publish_time_ns, &cdr)
            .with_context(at)?;
        count += 1;
    }
    Ok(count)
}
