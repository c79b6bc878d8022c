//! `msg_cdr`: converts messages between their JSON form and CDR, one per line.
//!
//! Encode (default): reads lines `{"type": "geometry_msgs/msg/PoseStamped", "value": {...}}` and
//! writes, for each, one line of lowercase hex: the CDR payload with its encapsulation header.
//! Decode (`--decode`): reads lines `{"type": ..., "hex": "0001..."}` and writes lines
//! `{"type": ..., "value": {...}}`. Blank lines are skipped. Non-finite floats are the strings
//! "NaN", "Infinity", "-Infinity" in JSON. The first bad line stops the run with an error naming
//! its line number (the output for earlier lines is already written).
//!
//! `--list` prints the known type names; `--schemas` prints each type's full definition.

use std::io::{BufRead, BufWriter, Write};

use anyhow::{Context, Result, anyhow, bail};
use clap::Parser;
use serde_json::Value;

/// Convert ROS 2 messages between JSON lines and hex CDR lines.
#[derive(Parser, Debug)]
#[command(name = "msg_cdr", version, about, long_about = None)]
struct Args {
    /// Decode `{"type", "hex"}` lines into `{"type", "value"}` lines instead of encoding.
    #[arg(long)]
    decode: bool,
    /// List the known message types and exit.
    #[arg(long)]
    list: bool,
    /// Write one JSON line per known type, `{"type", "dds_type", "definition"}` (the full
    /// `ros2msg` definition as rosbag2 stores it), and exit.
    #[arg(long, conflicts_with = "list")]
    schemas: bool,
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("msg_cdr: error: {}", describe(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes on one line, leaving out a cause whose text the previous message
/// already includes.
fn describe(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if !text.contains(&part) {
            if !text.is_empty() {
                text.push_str(": ");
            }
            text.push_str(&part);
        }
    }
    text
}

fn run() -> Result<()> {
    let args = Args::parse();
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    if args.list {
        for t in dynlab_msgs::all() {
            writeln!(out, "{}", t.type_name)?;
        }
        out.flush()?;
        return Ok(());
    }
    if args.schemas {
        for t in dynlab_msgs::all() {
            let line = serde_json::json!({
                "type": t.type_name,
                "dds_type": t.dds_type_name(),
                "definition": t.definition,
            });
            writeln!(out, "{line}")?;
        }
        out.flush()?;
        return Ok(());
    }
    let stdin = std::io::stdin();
    let result = convert(stdin.lock(), &mut out, args.decode);
    out.flush().context("writing output")?;
    result
}

fn convert(input: impl BufRead, out: &mut impl Write, decode: bool) -> Result<()> {
    for (index, line) in input.lines().enumerate() {
        let number = index + 1;
        let line = line.with_context(|| format!("line {number}: cannot read input"))?;
        if line.trim().is_empty() {
            continue;
        }
        let converted = if decode {
            decode_line(&line)
        } else {
            encode_line(&line)
        };
        let text = converted.with_context(|| format!("line {number}"))?;
        writeln!(out, "{text}")?;
    }
    Ok(())
}

fn message_type(record: &Value) -> Result<&'static dynlab_msgs::MessageType> {
    let name = record
        .get("type")
        .ok_or_else(|| {
            anyhow!("missing \"type\" (the ROS type name, e.g. \"geometry_msgs/msg/PoseStamped\")")
        })?
        .as_str()
        .ok_or_else(|| anyhow!("\"type\" must be a string"))?;
    dynlab_msgs::lookup(name).ok_or_else(|| {
        let known: Vec<&str> = dynlab_msgs::all().iter().map(|t| t.type_name).collect();
        anyhow!(
            "unknown message type `{name}`; known types: {}",
            known.join(", ")
        )
    })
}

fn parse_record(line: &str) -> Result<Value> {
    let record: Value = serde_json::from_str(line).context("not a JSON object")?;
    if !record.is_object() {
        bail!("not a JSON object");
    }
    Ok(record)
}

fn encode_line(line: &str) -> Result<String> {
    let record = parse_record(line)?;
    let t = message_type(&record)?;
    let value = record
        .get("value")
        .ok_or_else(|| anyhow!("missing \"value\" (the message as JSON)"))?;
    let bytes = (t.from_json)(value)?;
    Ok(to_hex(&bytes))
}

fn decode_line(line: &str) -> Result<String> {
    let record = parse_record(line)?;
    let t = message_type(&record)?;
    let hex = record
        .get("hex")
        .ok_or_else(|| anyhow!("missing \"hex\" (the CDR payload as hex)"))?
        .as_str()
        .ok_or_else(|| anyhow!("\"hex\" must be a string"))?;
    let bytes = from_hex(hex)?;
    let value = (t.to_json)(&bytes)?;
    let out = serde_json::json!({"type": t.type_name, "value": value});
    Ok(serde_json::to_string(&out)?)
}

fn to_hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        s.push(DIGITS[(b >> 4) as usize] as char);
        s.push(DIGITS[(b & 0xf) as usize] as char);
    }
    s
}

fn from_hex(hex: &str) -> Result<Vec<u8>> {
    let hex = hex.trim();
    if !hex.len().is_multiple_of(2) {
        bail!(
            "\"hex\" has an odd number of digits ({}); give two per byte",
            hex.len()
        );
    }
    let digit = |c: u8, at: usize| -> Result<u8> {
        (c as char)
            .to_digit(16)
            .map(|d| d as u8)
            .ok_or_else(|| anyhow!("\"hex\" has a non-hex character at position {at}"))
    };
    hex.as_bytes()
        .chunks(2)
        .enumerate()
        .map(|(i, pair)| Ok(digit(pair[0], 2 * i)? << 4 | digit(pair[1], 2 * i + 1)?))
        .collect()
}
