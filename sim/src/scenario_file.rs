//! Reading scenario files (TOML) with errors that name the offending key.

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::SimError;

/// Parses `text` as TOML into `T`; `origin` names the source in errors.
///
/// Unknown keys, wrong types and syntax errors come back as [`SimError::Parse`] whose message
/// starts with the dotted key (`effects.friction_patch.muu`) and the line number.
pub(crate) fn parse<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, SimError> {
    toml::from_str::<T>(text).map_err(|e| {
        let message = e.message().trim().to_string();
        let located = e
            .span()
            .map(|span| locate_key(text, span.start))
            .map(|(key, line)| {
                let hint = if message.starts_with("unknown field") {
                    " (remove it or fix its spelling)"
                } else {
                    ""
                };
                if key.is_empty() {
                    format!("line {line}: {message}{hint}")
                } else {
                    format!("key `{key}` (line {line}): {message}{hint}")
                }
            })
            .unwrap_or(message);
        SimError::Parse {
            origin: origin.to_string(),
            message: located,
        }
    })
}

/// Reads and parses a scenario file.
pub(crate) fn load<T: DeserializeOwned>(path: &Path) -> Result<T, SimError> {
    let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, &path.display().to_string())
}

/// The dotted key at byte `offset` (table header plus the key on that line) and the 1-based line.
fn locate_key(text: &str, offset: usize) -> (String, usize) {
    let offset = offset.min(text.len());
    let before = text.get(..offset).unwrap_or("");
    let line_no = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next().unwrap_or("");
    let mut table = String::new();
    for l in text[..line_start].lines() {
        if let Some(h) = header(l) {
            table = h;
        }
    }
    let trimmed = line.trim();
    let key = if let Some(h) = header(trimmed) {
        h
    } else if let Some((k, _)) = trimmed.split_once('=') {
        let k = k.trim().trim_matches('"').trim_matches('\'').to_string();
        if table.is_empty() {
            k
        } else {
            format!("{table}.{k}")
        }
    } else {
        table
    };
    (key, line_no)
}

fn header(line: &str) -> Option<String> {
    let t = line.trim();
    let inner = t
        .strip_prefix("[[")
        .and_then(|s| s.split_once("]]"))
        .map(|(h, _)| h);
    let inner = inner.or_else(|| {
        t.strip_prefix('[')
            .and_then(|s| s.split_once(']'))
            .map(|(h, _)| h)
    });
    inner.map(|h| h.trim().to_string())
}
