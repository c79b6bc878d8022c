//! Full `ros2msg` definitions, composed exactly the way rosbag2 (Jazzy) stores them in MCAP.
//!
//! rosbag2 (`rosbag2_cpp::LocalMessageDefinitionSource::get_full_text`) builds a schema from the
//! `.msg` files like this, and [`compose`] does the same:
//!
//! 1. Start with the root type's own `.msg` text, verbatim (it ends with a newline).
//! 2. Its dependencies are the first word of every line that starts (after optional
//!    whitespace) with a type name followed by whitespace, less the primitive types; a name without
//!    a package gets the package of the type being read (`Pose pose` in `geometry_msgs` means
//!    `geometry_msgs/Pose`). They form a *sorted set* (byte order), not field order.
//! 3. For each dependency not yet written anywhere in the schema: append `"\n"`, a line of 80 `=`,
//!    a line `MSG: package/Type`, then — recursively, depth first — that type's text and its own
//!    unwritten dependencies.
//!
//! So every dependency appears once, a blank line precedes each separator, and `MSG:` lines use
//! the short `package/Type` form. For `geometry_msgs/msg/PoseStamped` the blocks are, in order:
//! PoseStamped, `geometry_msgs/Pose`, `geometry_msgs/Point`, `geometry_msgs/Quaternion`,
//! `std_msgs/Header`, `builtin_interfaces/Time`.
//!
//! (The Python `rosbags` writer differs: it walks fields in declaration order and puts no blank
//! line before a separator. Readers — rosbags, mcap-ros2-support, Foxglove — accept both.)
//!
//! The texts of our standard types carry every field, constant and default value of the ROS 2
//! Jazzy interfaces, with comments of our own; a schema written by `ros2 bag record` carries the
//! upstream comments instead, so the two differ only in comment lines.

use std::collections::{BTreeSet, HashSet};

use crate::RosMessage;

/// The separator line before each dependency's block: 80 `=` characters.
pub const SEPARATOR: &str =
    "================================================================================";

/// The primitive `.msg` field types, which are not dependencies.
pub const PRIMITIVE_TYPES: [&str; 14] = [
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string",
];

/// Problems with a message definition.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DefinitionError {
    /// A type name is not `package/Type` or `package/msg/Type`.
    #[error("`{0}` is not a message type name: expected `package/Type` or `package/msg/Type`")]
    InvalidTypeName(String),
    /// No `.msg` text is known for a type the definition needs.
    #[error("no .msg text for `{missing}`, which `{needed_by}` uses: add its definition")]
    NotFound {
        /// The type without a definition.
        missing: String,
        /// The type whose field uses it.
        needed_by: String,
    },
    /// A dependency block is not introduced by a `MSG: package/Type` line.
    #[error("block {index} after a separator line does not start with `MSG: package/Type`")]
    MissingMsgLine {
        /// 1-based number of the block (the root text is block 0).
        index: usize,
    },
    /// The same type has two blocks.
    #[error("`{0}` has more than one MSG block; each dependency must appear exactly once")]
    Duplicate(String),
    /// A block for a type nothing references.
    #[error("`{0}` has a MSG block but no field uses it")]
    Unused(String),
}

/// One `.msg` text inside a full definition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DefinitionBlock<'a> {
    /// The type named on the block's `MSG:` line; `None` for the root (first) block.
    pub type_name: Option<&'a str>,
    /// The block's `.msg` text (without separator and `MSG:` lines).
    pub text: &'a str,
}

/// `(package, Type)` of `package/Type` or `package/msg/Type` (also `srv`, `action`, any
/// namespace), if the name has that shape.
pub fn split_type_name(name: &str) -> Option<(&str, &str)> {
    let valid = |part: &str| {
        let mut chars = part.chars();
        chars.next().is_some_and(|c| c.is_ascii_alphabetic())
            && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [pkg, ty] | [pkg, _, ty] if parts.iter().all(|p| valid(p)) => Some((pkg, ty)),
        _ => None,
    }
}

/// The dependencies of one `.msg` text, by rosbag2's rule (see the module docs): non-primitive
/// field types as `package/Type`, sorted, each once. `package` qualifies bare type names.
pub fn dependencies(text: &str, package: &str) -> BTreeSet<String> {
    let mut deps = BTreeSet::new();
    // `split_inclusive` keeps each line's '\n', which counts as the whitespace after a type.
    for line in text.split_inclusive('\n') {
        let line = line.trim_start_matches([' ', '\t', '\r']);
        let end = line
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '/'))
            .unwrap_or(line.len());
        let (ty, mut rest) = line.split_at(end);
        if ty.is_empty() {
            continue;
        }
        // An optional array suffix: `[]`, `[36]`, `[<=10]`.
        if let Some(after) = rest.strip_prefix('[') {
            match after.find(']') {
                Some(close) => rest = &after[close + 1..],
                None => continue,
            }
        }
        // rosbag2's pattern needs whitespace after the type (`string<=10 s` has none).
        if !rest.starts_with(char::is_whitespace) {
            continue;
        }
        if PRIMITIVE_TYPES.contains(&ty) {
            continue;
        }
        deps.insert(if ty.contains('/') {
            ty.to_string()
        } else {
            format!("{package}/{ty}")
        });
    }
    deps
}

/// Composes the full definition of `root` as rosbag2 does (see the module docs), looking up each
/// type's own `.msg` text with `msg_text`, which is asked for `root` as given and for
/// dependencies as `package/Type`.
pub fn compose<'a>(
    root: &str,
    msg_text: impl Fn(&str) -> Option<&'a str>,
) -> Result<String, DefinitionError> {
    fn append<'a>(
        name: &str,
        text: &str,
        msg_text: &dyn Fn(&str) -> Option<&'a str>,
        seen: &mut HashSet<String>,
        out: &mut String,
    ) -> Result<(), DefinitionError> {
        let (package, _) =
            split_type_name(name).ok_or_else(|| DefinitionError::InvalidTypeName(name.into()))?;
        out.push_str(text);
        for dep in dependencies(text, package) {
            if !seen.insert(dep.clone()) {
                continue;
            }
            let dep_text = msg_text(&dep).ok_or_else(|| DefinitionError::NotFound {
                missing: dep.clone(),
                needed_by: name.to_string(),
            })?;
            out.push('\n');
            out.push_str(SEPARATOR);
            out.push_str("\nMSG: ");
            out.push_str(&dep);
            out.push('\n');
            append(&dep, dep_text, msg_text, seen, out)?;
        }
        Ok(())
    }
    let text = msg_text(root).ok_or_else(|| DefinitionError::NotFound {
        missing: root.to_string(),
        needed_by: root.to_string(),
    })?;
    let mut out = String::new();
    append(root, text, &msg_text, &mut HashSet::new(), &mut out)?;
    Ok(out)
}

/// Splits a full definition into its blocks: the root text first, then one block per `MSG:`
/// line. Accepts rosbag2's layout and the rosbags layout (no blank line before separators).
pub fn blocks(full: &str) -> Result<Vec<DefinitionBlock<'_>>, DefinitionError> {
    let mut out = Vec::new();
    let mut rest = full;
    let mut name = None;
    loop {
        // The next separator line (a line that is exactly SEPARATOR).
        let mut search = 0;
        let sep = loop {
            match rest[search..].find(SEPARATOR) {
                None => break None,
                Some(i) => {
                    let at = search + i;
                    let line_start = at == 0 || rest.as_bytes()[at - 1] == b'\n';
                    let after = &rest[at + SEPARATOR.len()..];
                    let line_end = after.is_empty() || after.starts_with('\n');
                    if line_start && line_end {
                        break Some(at);
                    }
                    search = at + SEPARATOR.len();
                }
            }
        };
        let Some(at) = sep else {
            out.push(DefinitionBlock {
                type_name: name,
                text: rest,
            });
            return Ok(out);
        };
        out.push(DefinitionBlock {
            type_name: name,
            text: &rest[..at],
        });
        let after = rest[at + SEPARATOR.len()..]
            .strip_prefix('\n')
            .unwrap_or("");
        let (msg_line, body) = after.split_once('\n').unwrap_or((after, ""));
        let type_name = msg_line
            .strip_prefix("MSG: ")
            .map(str::trim)
            .filter(|n| split_type_name(n).is_some())
            .ok_or(DefinitionError::MissingMsgLine { index: out.len() })?;
        name = Some(type_name);
        rest = body;
    }
}

/// Checks a full definition of `root`: every type a block uses has exactly one `MSG:` block, and
/// every `MSG:` block is used.
pub fn check(full: &str, root: &str) -> Result<(), DefinitionError> {
    let short = |name: &str| -> Result<String, DefinitionError> {
        split_type_name(name)
            .map(|(p, t)| format!("{p}/{t}"))
            .ok_or_else(|| DefinitionError::InvalidTypeName(name.into()))
    };
    let root = short(root)?;
    let blocks = blocks(full)?;
    let mut named = Vec::with_capacity(blocks.len());
    let mut defined = HashSet::new();
    for block in &blocks {
        let name = match block.type_name {
            None => root.clone(),
            Some(n) => {
                let n = short(n)?;
                if !defined.insert(n.clone()) {
                    return Err(DefinitionError::Duplicate(n));
                }
                n
            }
        };
        named.push((name, block.text));
    }
    let mut used = HashSet::new();
    for (name, text) in &named {
        let package = name.split('/').next().unwrap_or_default();
        for dep in dependencies(text, package) {
            if dep != root && !defined.contains(&dep) {
                return Err(DefinitionError::NotFound {
                    missing: dep,
                    needed_by: name.clone(),
                });
            }
            used.insert(dep);
        }
    }
    match defined.into_iter().find(|d| !used.contains(d)) {
        Some(unused) => Err(DefinitionError::Unused(unused)),
        None => Ok(()),
    }
}

/// Lists every message type of this crate once, as type paths, for tables built from all of them.
macro_rules! msg_text_table {
    ($($t:ty),* $(,)?) => {
        &[$((<$t as RosMessage>::TYPE_NAME, <$t as RosMessage>::MSG_TEXT)),*]
    };
}

/// `(type name, own .msg text)` of every message type of this crate.
pub(crate) const KNOWN_MSG_TEXTS: &[(&str, &str)] = with_all_message_types!(msg_text_table);

/// The own `.msg` text of one of this crate's types, by `package/Type` or `package/msg/Type`.
pub fn known_msg_text(name: &str) -> Option<&'static str> {
    let (package, ty) = split_type_name(name)?;
    KNOWN_MSG_TEXTS
        .iter()
        .find(|(known, _)| split_type_name(known) == Some((package, ty)))
        .map(|(_, text)| *text)
}

/// The full definition of one of this crate's types.
pub(crate) fn known_full_text(root: &'static str) -> String {
    // Every dependency of every type here has its text in KNOWN_MSG_TEXTS (a unit test composes
    // and checks all of them), so this cannot fail.
    compose(root, known_msg_text)
        .unwrap_or_else(|e| panic!("dynlab-msgs bug: cannot compose {root}: {e}"))
}
