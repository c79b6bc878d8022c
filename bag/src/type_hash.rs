//! The RIHS01 type hash ROS 2 (Iron and later) gives every interface type, which rosbag2 Jazzy
//! stores as `topic_type_hash` in MCAP channel metadata and as `type_description_hash` in
//! `metadata.yaml`.
//!
//! The hash is the SHA-256 of a JSON rendering of the type description (REP 2011): the type's
//! fields, each with a numeric field type id, array capacity, string capacity and nested type
//! name, followed by the descriptions of every referenced type sorted by name. Default values,
//! constants and comments do not enter the hash. The description is rebuilt here from the
//! `ros2msg` definition text (the main type followed by its dependencies), so it works for any
//! type whose full definition is known.
//!
//! `char` maps to `uint8` and `byte` to `octet`, as `rosidl_adapter` translates `.msg` to IDL.

use std::collections::BTreeMap;

use sha2::{Digest, Sha256};

const NESTED: u8 = 1;
const BOUNDED_STRING: u8 = 21;
const BOUNDED_WSTRING: u8 = 22;
const ARRAY_OFFSET: u8 = 48;
const BOUNDED_SEQUENCE_OFFSET: u8 = 96;
const UNBOUNDED_SEQUENCE_OFFSET: u8 = 144;

fn primitive_id(name: &str) -> Option<u8> {
    Some(match name {
        "int8" => 2,
        "uint8" | "char" => 3,
        "int16" => 4,
        "uint16" => 5,
        "int32" => 6,
        "uint32" => 7,
        "int64" => 8,
        "uint64" => 9,
        "float32" => 10,
        "float64" => 11,
        "bool" => 15,
        "byte" => 16,
        "string" => 17,
        "wstring" => 18,
        _ => return None,
    })
}

#[derive(Debug, Clone, PartialEq)]
struct FieldType {
    type_id: u8,
    capacity: u64,
    string_capacity: u64,
    nested_type_name: String,
}

#[derive(Debug, Clone, PartialEq)]
struct Field {
    name: String,
    ty: FieldType,
}

/// `pkg/Type` or `pkg/msg/Type` → `pkg/msg/Type`; a bare `Type` is looked up in `package`.
fn full_type_name(name: &str, package: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [pkg, ty] => format!("{pkg}/msg/{ty}"),
        [_, _, _] => name.to_string(),
        ["Header"] => "std_msgs/msg/Header".to_string(),
        _ => format!("{package}/msg/{name}"),
    }
}

fn parse_type(token: &str, package: &str) -> Option<FieldType> {
    let (base, offset, capacity) = match token.find('[') {
        Some(open) => {
            let inner = token.get(open + 1..token.len().checked_sub(1)?)?;
            if !token.ends_with(']') {
                return None;
            }
            let base = &token[..open];
            if inner.is_empty() {
                (base, UNBOUNDED_SEQUENCE_OFFSET, 0)
            } else if let Some(n) = inner.strip_prefix("<=") {
                (base, BOUNDED_SEQUENCE_OFFSET, n.trim().parse().ok()?)
            } else {
                (base, ARRAY_OFFSET, inner.trim().parse().ok()?)
            }
        }
        None => (token, 0, 0),
    };
    let (type_id, string_capacity, nested) = if let Some(n) = base.strip_prefix("string<=") {
        (BOUNDED_STRING, n.parse().ok()?, String::new())
    } else if let Some(n) = base.strip_prefix("wstring<=") {
        (BOUNDED_WSTRING, n.parse().ok()?, String::new())
    } else if let Some(id) = primitive_id(base) {
        (id, 0, String::new())
    } else {
        if base.is_empty()
            || !base
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "_/".contains(c))
        {
            return None;
        }
        (NESTED, 0, full_type_name(base, package))
    };
    Some(FieldType {
        type_id: type_id + offset,
        capacity,
        string_capacity,
        nested_type_name: nested,
    })
}

/// Fields of one `.msg` text; `None` if a line is not understood.
fn parse_fields(text: &str, package: &str) -> Option<Vec<Field>> {
    let mut fields = Vec::new();
    for line in text.lines() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut tokens = line.split_whitespace();
        let ty = tokens.next()?;
        let name = tokens.next()?;
        // Constants: `int32 FOO=1` or `int32 FOO = 1`.
        if name.contains('=') || tokens.next().is_some_and(|t| t.starts_with('=')) {
            continue;
        }
        fields.push(Field {
            name: name.to_string(),
            ty: parse_type(ty, package)?,
        });
    }
    if fields.is_empty() {
        fields.push(Field {
            name: "structure_needs_at_least_one_member".into(),
            ty: FieldType {
                type_id: 3,
                capacity: 0,
                string_capacity: 0,
                nested_type_name: String::new(),
            },
        });
    }
    Some(fields)
}

/// Splits a rosbag2 `ros2msg` definition into (full type name, own text) blocks.
fn split_definition(type_name: &str, definition: &str) -> Option<BTreeMap<String, String>> {
    let mut blocks = BTreeMap::new();
    let mut current = type_name.to_string();
    let mut text = String::new();
    for line in definition.lines() {
        if line.len() >= 3 && line.trim().chars().all(|c| c == '=') {
            blocks.insert(std::mem::take(&mut current), std::mem::take(&mut text));
            continue;
        }
        if current.is_empty() {
            let name = line.trim().strip_prefix("MSG:")?.trim();
            current = full_type_name(name, "");
            continue;
        }
        text.push_str(line);
        text.push('\n');
    }
    if current.is_empty() {
        return None;
    }
    blocks.insert(current, text);
    Some(blocks)
}

fn json_str(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 || (c as u32) > 0x7e => {
                let mut buf = [0u16; 2];
                for unit in c.encode_utf16(&mut buf) {
                    out.push_str(&format!("\\u{unit:04x}"));
                }
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn struct_json(name: &str, fields: &[Field]) -> String {
    let fields: Vec<String> = fields
        .iter()
        .map(|f| {
            format!(
                "{{\"name\": {}, \"type\": {{\"type_id\": {}, \"capacity\": {}, \
                 \"string_capacity\": {}, \"nested_type_name\": {}}}}}",
                json_str(&f.name),
                f.ty.type_id,
                f.ty.capacity,
                f.ty.string_capacity,
                json_str(&f.ty.nested_type_name)
            )
        })
        .collect();
    format!(
        "{{\"type_name\": {}, \"fields\": [{}]}}",
        json_str(name),
        fields.join(", ")
    )
}

/// The RIHS01 hash (`RIHS01_<64 hex digits>`) of `type_name` given its full `ros2msg`
/// definition (own text, then each dependency after a line of `=` and a `MSG: pkg/Type` line).
/// `None` when the text does not parse or a referenced type's definition is missing; rosbag2
/// then stores an empty hash, as it does for types it cannot describe.
pub fn rihs01(type_name: &str, definition: &str) -> Option<String> {
    let package = type_name.split('/').next()?;
    if type_name.split('/').count() != 3 {
        return None;
    }
    let blocks = split_definition(type_name, definition)?;
    let mut parsed: BTreeMap<String, Vec<Field>> = BTreeMap::new();
    let mut todo = vec![type_name.to_string()];
    while let Some(name) = todo.pop() {
        if parsed.contains_key(&name) {
            continue;
        }
        let text = blocks.get(&name)?;
        let pkg = if name == type_name {
            package
        } else {
            name.split('/').next()?
        };
        let fields = parse_fields(text, pkg)?;
        for f in &fields {
            if !f.ty.nested_type_name.is_empty() {
                todo.push(f.ty.nested_type_name.clone());
            }
        }
        parsed.insert(name, fields);
    }
    let main = struct_json(type_name, parsed.get(type_name)?);
    let referenced: Vec<String> = parsed
        .iter()
        .filter(|(name, _)| name.as_str() != type_name)
        .map(|(name, fields)| struct_json(name, fields))
        .collect();
    let json = format!(
        "{{\"type_description\": {main}, \"referenced_type_descriptions\": [{}]}}",
        referenced.join(", ")
    );
    let digest = Sha256::digest(json.as_bytes());
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    Some(format!("RIHS01_{hex}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_arrays_strings_and_constants() {
        let f = parse_fields(
            "# comment\nint32 A=1\nuint8 B = 2\nfloat64[3] x  # c\nstring<=5 s\nPoint[] p\n\
             byte[<=4] b\nstd_msgs/Header h\nfloat64 w 1.0\n",
            "geometry_msgs",
        )
        .unwrap();
        let ids: Vec<(u8, u64, u64, &str)> = f
            .iter()
            .map(|f| {
                (
                    f.ty.type_id,
                    f.ty.capacity,
                    f.ty.string_capacity,
                    f.ty.nested_type_name.as_str(),
                )
            })
            .collect();
        assert_eq!(
            ids,
            vec![
                (11 + 48, 3, 0, ""),
                (21, 0, 5, ""),
                (1 + 144, 0, 0, "geometry_msgs/msg/Point"),
                (16 + 96, 4, 0, ""),
                (1, 0, 0, "std_msgs/msg/Header"),
                (11, 0, 0, ""),
            ]
        );
    }

    #[test]
    fn missing_dependency_gives_none() {
        assert!(rihs01("geometry_msgs/msg/Pose", "Point position\n").is_none());
        assert!(rihs01("bad", "int32 a\n").is_none());
    }

    #[test]
    fn empty_message_gets_placeholder_member() {
        let h = rihs01("std_msgs/msg/Empty", "").unwrap();
        assert!(h.starts_with("RIHS01_") && h.len() == 7 + 64);
    }

    /// The published hash of `builtin_interfaces/msg/Time` (it appears in every ROS 2 Jazzy
    /// type description that uses a stamp).
    #[test]
    fn builtin_time_matches_ros() {
        assert_eq!(
            rihs01("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n").unwrap(),
            "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
        );
    }
}
