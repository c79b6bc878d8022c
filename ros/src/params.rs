//! Node parameters: YAML-typed values from `-p name:=value` and `--params-file`, with typed access
//! whose errors name the key, the expected type and where the value came from.
//!
//! A params file is the ROS 2 layout: node names (optionally with namespace, `*` for one token and
//! `**` for any number of tokens, so `/**` matches every node) mapping to `ros__parameters:`, under
//! which nested keys are flattened with `.` (`mppi: {samples: 256}` → `mppi.samples`). Sections
//! and `-p` overrides are applied in command-line order, later ones winning, as rclcpp does.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use serde_yaml::Value;

use crate::param_store::ParamStore;

/// A parameter value, with the types ROS 2 parameters have.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    /// `bool`.
    Bool(bool),
    /// `integer` (64-bit).
    Integer(i64),
    /// `double`.
    Double(f64),
    /// `string`.
    String(String),
    /// `bool_array`.
    BoolArray(Vec<bool>),
    /// `integer_array`.
    IntegerArray(Vec<i64>),
    /// `double_array`.
    DoubleArray(Vec<f64>),
    /// `string_array`.
    StringArray(Vec<String>),
}

impl ParamValue {
    /// The ROS 2 name of this value's type (`integer`, `double_array`, …).
    pub fn type_name(&self) -> &'static str {
        match self {
            ParamValue::Bool(_) => "bool",
            ParamValue::Integer(_) => "integer",
            ParamValue::Double(_) => "double",
            ParamValue::String(_) => "string",
            ParamValue::BoolArray(_) => "bool_array",
            ParamValue::IntegerArray(_) => "integer_array",
            ParamValue::DoubleArray(_) => "double_array",
            ParamValue::StringArray(_) => "string_array",
        }
    }

    /// Parses a command-line value as YAML, as rcl does: `100` is an integer, `100.0` a double,
    /// `true` a bool, `[1, 2]` an integer array, anything else a string.
    pub fn parse(text: &str) -> Result<ParamValue, String> {
        if text.trim().is_empty() {
            return Ok(ParamValue::String(text.to_owned()));
        }
        match serde_yaml::from_str::<Value>(text) {
            Ok(v) => ParamValue::from_yaml(&v),
            // Text YAML cannot read (e.g. `a: b: c`) is taken literally as a string.
            Err(_) => Ok(ParamValue::String(text.to_owned())),
        }
    }

    /// Converts a YAML scalar or homogeneous sequence. Integers mixed into a double sequence are
    /// promoted to doubles.
    pub fn from_yaml(v: &Value) -> Result<ParamValue, String> {
        match v {
            Value::Bool(b) => Ok(ParamValue::Bool(*b)),
            Value::Number(n) => {
                if let Some(i) = n.as_i64() {
                    Ok(ParamValue::Integer(i))
                } else if let Some(f) = n.as_f64() {
                    if n.is_u64() {
                        Err(format!(
                            "integer {n} does not fit in a 64-bit signed integer"
                        ))
                    } else {
                        Ok(ParamValue::Double(f))
                    }
                } else {
                    Err(format!("number {n} is not representable"))
                }
            }
            Value::String(s) => Ok(ParamValue::String(s.clone())),
            Value::Sequence(items) => sequence(items),
            Value::Null => Err("empty value: give a value after `:`".to_owned()),
            Value::Mapping(_) => Err("a mapping is not a parameter value".to_owned()),
            Value::Tagged(t) => ParamValue::from_yaml(&t.value),
        }
    }
}

fn sequence(items: &[Value]) -> Result<ParamValue, String> {
    let scalars = items
        .iter()
        .map(ParamValue::from_yaml)
        .collect::<Result<Vec<_>, _>>()?;
    if scalars.is_empty() {
        return Ok(ParamValue::StringArray(Vec::new()));
    }
    let all = |f: fn(&ParamValue) -> bool| scalars.iter().all(f);
    if all(|v| matches!(v, ParamValue::Bool(_))) {
        Ok(ParamValue::BoolArray(
            scalars
                .iter()
                .filter_map(|v| {
                    if let ParamValue::Bool(b) = v {
                        Some(*b)
                    } else {
                        None
                    }
                })
                .collect(),
        ))
    } else if all(|v| matches!(v, ParamValue::Integer(_))) {
        Ok(ParamValue::IntegerArray(
            scalars
                .iter()
                .filter_map(|v| {
                    if let ParamValue::Integer(i) = v {
                        Some(*i)
                    } else {
                        None
                    }
                })
                .collect(),
        ))
    } else if all(|v| matches!(v, ParamValue::Integer(_) | ParamValue::Double(_))) {
        Ok(ParamValue::DoubleArray(
            scalars
                .iter()
                .filter_map(|v| match v {
                    ParamValue::Integer(i) => Some(*i as f64),
                    ParamValue::Double(d) => Some(*d),
                    _ => None,
                })
                .collect(),
        ))
    } else if all(|v| matches!(v, ParamValue::String(_))) {
        Ok(ParamValue::StringArray(
            scalars
                .iter()
                .filter_map(|v| {
                    if let ParamValue::String(s) = v {
                        Some(s.clone())
                    } else {
                        None
                    }
                })
                .collect(),
        ))
    } else {
        Err(
            "array mixes types: ROS 2 arrays hold one type (bool, integer, double or string)"
                .to_owned(),
        )
    }
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Bool(v) => write!(f, "{v}"),
            ParamValue::Integer(v) => write!(f, "{v}"),
            ParamValue::Double(v) => write!(f, "{v:?}"),
            ParamValue::String(v) => write!(f, "'{v}'"),
            ParamValue::BoolArray(v) => write!(f, "{v:?}"),
            ParamValue::IntegerArray(v) => write!(f, "{v:?}"),
            ParamValue::DoubleArray(v) => write!(f, "{v:?}"),
            ParamValue::StringArray(v) => write!(f, "{v:?}"),
        }
    }
}

/// Where a parameter's value came from.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamSource {
    /// `-p name:=value` on the command line.
    CommandLine,
    /// A `--params-file`, in the section for the named node pattern.
    ParamsFile {
        /// The file.
        path: PathBuf,
        /// The section key that matched the node (e.g. `/**` or `/recorder`).
        section: String,
    },
    /// Set by the node's own code.
    Code,
}

impl fmt::Display for ParamSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamSource::CommandLine => write!(f, "`-p` on the command line"),
            ParamSource::ParamsFile { path, section } => {
                write!(f, "params file {} (section `{section}`)", path.display())
            }
            ParamSource::Code => write!(f, "the node's code"),
        }
    }
}

/// A value with its source.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// The value.
    pub value: ParamValue,
    /// Where it came from.
    pub source: ParamSource,
}

/// Errors from reading parameters.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// A value has another type than the node expects.
    #[error(
        "parameter `{key}` is a {found} ({value}) from {origin}, but the node expects {expected}: \
         set e.g. `-p {key}:={example}`"
    )]
    WrongType {
        /// The key.
        key: String,
        /// The type the node expects.
        expected: &'static str,
        /// An example of a valid value.
        example: &'static str,
        /// The type found.
        found: &'static str,
        /// The value found.
        value: String,
        /// Where the value came from.
        origin: Box<ParamSource>,
    },
    /// A value has the right type but is out of range.
    #[error("parameter `{key}` = {value} from {origin} is out of range: {reason}")]
    OutOfRange {
        /// The key.
        key: String,
        /// The value found.
        value: String,
        /// Why it is out of range.
        reason: String,
        /// Where the value came from.
        origin: Box<ParamSource>,
    },
    /// A required parameter is not set.
    #[error(
        "parameter `{key}` ({expected}) is required by node {node}: set it with `-p {key}:=<value>` \
         or in a params file under `{node}: ros__parameters:`"
    )]
    Missing {
        /// The key.
        key: String,
        /// The type the node expects.
        expected: &'static str,
        /// The node's fully qualified name.
        node: String,
    },
    /// A params file could not be read.
    #[error("cannot read params file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A params file is not YAML or not in the ROS 2 layout.
    #[error("params file {path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// Conversion from a parameter value to a Rust type, for typed access.
pub trait FromParam: Sized {
    /// The ROS 2 type name the node expects (for error messages).
    const EXPECTED: &'static str;
    /// An example of a valid command-line value (for error messages).
    const EXAMPLE: &'static str;
    /// Converts, or `Err(None)` on a type mismatch, `Err(Some(reason))` when out of range.
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>>;
    /// The parameter value of `self` (the inverse of `from_param`), as the parameter services
    /// report it.
    fn to_param(&self) -> ParamValue;
}

impl FromParam for bool {
    fn to_param(&self) -> ParamValue {
        ParamValue::Bool(*self)
    }
    const EXPECTED: &'static str = "a bool";
    const EXAMPLE: &'static str = "true";
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::Bool(b) => Ok(*b),
            _ => Err(None),
        }
    }
}

impl FromParam for i64 {
    fn to_param(&self) -> ParamValue {
        ParamValue::Integer(*self)
    }
    const EXPECTED: &'static str = "an integer";
    const EXAMPLE: &'static str = "10";
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::Integer(i) => Ok(*i),
            _ => Err(None),
        }
    }
}

macro_rules! narrow_int {
    ($t:ty, $expected:literal) => {
        impl FromParam for $t {
            const EXPECTED: &'static str = $expected;
            const EXAMPLE: &'static str = "10";
            fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
                match value {
                    ParamValue::Integer(i) => <$t>::try_from(*i)
                        .map_err(|_| Some(format!("must be in {}..={}", <$t>::MIN, <$t>::MAX))),
                    _ => Err(None),
                }
            }
            fn to_param(&self) -> ParamValue {
                ParamValue::Integer(i64::try_from(*self).unwrap_or(i64::MAX))
            }
        }
    };
}
narrow_int!(i32, "an integer (32-bit)");
narrow_int!(u32, "a non-negative integer (32-bit)");
narrow_int!(u64, "a non-negative integer");
narrow_int!(usize, "a non-negative integer");
narrow_int!(u16, "a non-negative integer (16-bit)");

impl FromParam for f64 {
    fn to_param(&self) -> ParamValue {
        ParamValue::Double(*self)
    }
    const EXPECTED: &'static str = "a double";
    const EXAMPLE: &'static str = "1.5";
    /// Integers are accepted too (`-p rate:=100` means 100.0).
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::Double(d) => Ok(*d),
            ParamValue::Integer(i) => Ok(*i as f64),
            _ => Err(None),
        }
    }
}

impl FromParam for String {
    fn to_param(&self) -> ParamValue {
        ParamValue::String(self.clone())
    }
    const EXPECTED: &'static str = "a string";
    const EXAMPLE: &'static str = "text";
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::String(s) => Ok(s.clone()),
            _ => Err(None),
        }
    }
}

fn is_empty_array(value: &ParamValue) -> bool {
    matches!(value, ParamValue::StringArray(v) if v.is_empty())
        || matches!(value, ParamValue::IntegerArray(v) if v.is_empty())
        || matches!(value, ParamValue::DoubleArray(v) if v.is_empty())
        || matches!(value, ParamValue::BoolArray(v) if v.is_empty())
}

impl FromParam for Vec<f64> {
    fn to_param(&self) -> ParamValue {
        ParamValue::DoubleArray(self.clone())
    }
    const EXPECTED: &'static str = "a double_array";
    const EXAMPLE: &'static str = "[1.0, 2.5]";
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::DoubleArray(v) => Ok(v.clone()),
            ParamValue::IntegerArray(v) => Ok(v.iter().map(|&i| i as f64).collect()),
            v if is_empty_array(v) => Ok(Vec::new()),
            _ => Err(None),
        }
    }
}

impl FromParam for Vec<i64> {
    fn to_param(&self) -> ParamValue {
        ParamValue::IntegerArray(self.clone())
    }
    const EXPECTED: &'static str = "an integer_array";
    const EXAMPLE: &'static str = "[1, 2]";
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::IntegerArray(v) => Ok(v.clone()),
            v if is_empty_array(v) => Ok(Vec::new()),
            _ => Err(None),
        }
    }
}

impl FromParam for Vec<bool> {
    fn to_param(&self) -> ParamValue {
        ParamValue::BoolArray(self.clone())
    }
    const EXPECTED: &'static str = "a bool_array";
    const EXAMPLE: &'static str = "[true, false]";
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::BoolArray(v) => Ok(v.clone()),
            v if is_empty_array(v) => Ok(Vec::new()),
            _ => Err(None),
        }
    }
}

impl FromParam for Vec<String> {
    fn to_param(&self) -> ParamValue {
        ParamValue::StringArray(self.clone())
    }
    const EXPECTED: &'static str = "a string_array";
    const EXAMPLE: &'static str = "[a, b]";
    fn from_param(value: &ParamValue) -> Result<Self, Option<String>> {
        match value {
            ParamValue::StringArray(v) => Ok(v.clone()),
            v if is_empty_array(v) => Ok(Vec::new()),
            _ => Err(None),
        }
    }
}

/// The parameters of one node, after applying params files and `-p` overrides.
///
/// With [`Parameters::record_into`], every value the node reads (`get`, `get_or`, `require`) is
/// also declared, read-only and with the value the node uses (its default when none was given),
/// in the store the parameter services answer from: `ros2 param list/get/dump` show what the
/// node runs with.
#[derive(Debug, Clone, Default)]
pub struct Parameters {
    node: String,
    values: BTreeMap<String, Param>,
    record: Option<Arc<Mutex<ParamStore>>>,
}

impl Parameters {
    /// An empty set for the node with this fully qualified name.
    pub fn new(node_fqn: &str) -> Parameters {
        Parameters {
            node: node_fqn.to_owned(),
            values: BTreeMap::new(),
            record: None,
        }
    }

    /// Declares every value read from now on in `store` (read-only, as used by the node).
    pub fn record_into(&mut self, store: Arc<Mutex<ParamStore>>) {
        self.record = Some(store);
    }

    fn recorded<T: FromParam>(&self, key: &str, value: &T) {
        if let Some(store) = &self.record {
            let origin = match self.values.get(key) {
                Some(p) => format!("set at start from {}", p.source),
                None => "the node's default".to_owned(),
            };
            store
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .declare_if_absent(
                    key,
                    value.to_param(),
                    &format!(
                        "read-only ({origin}); restart the node with -p {key}:=value to change it"
                    ),
                );
        }
    }

    /// The node these parameters belong to.
    pub fn node(&self) -> &str {
        &self.node
    }

    /// Sets a value (later sets win).
    pub fn set(&mut self, key: &str, value: ParamValue, source: ParamSource) {
        self.values.insert(key.to_owned(), Param { value, source });
    }

    /// The raw entry for a key.
    pub fn entry(&self, key: &str) -> Option<&Param> {
        self.values.get(key)
    }

    /// Every key and entry, sorted by key.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &Param)> {
        self.values.iter().map(|(k, p)| (k.as_str(), p))
    }

    /// Keys that are set but not among `known` — typically typos worth a warning.
    pub fn unknown_keys<'a>(&'a self, known: &[&str]) -> Vec<&'a str> {
        self.values
            .keys()
            .map(String::as_str)
            .filter(|k| !known.contains(k))
            .collect()
    }

    /// The value of `key` as `T`, or `None` when it is not set.
    pub fn get<T: FromParam>(&self, key: &str) -> Result<Option<T>, ParamError> {
        let Some(p) = self.values.get(key) else {
            return Ok(None);
        };
        T::from_param(&p.value)
            .inspect(|v| self.recorded(key, v))
            .map(Some)
            .map_err(|reason| match reason {
                None => ParamError::WrongType {
                    key: key.to_owned(),
                    expected: T::EXPECTED,
                    example: T::EXAMPLE,
                    found: p.value.type_name(),
                    value: p.value.to_string(),
                    origin: Box::new(p.source.clone()),
                },
                Some(reason) => ParamError::OutOfRange {
                    key: key.to_owned(),
                    value: p.value.to_string(),
                    reason,
                    origin: Box::new(p.source.clone()),
                },
            })
    }

    /// The value of `key` as `T`, or `default` when it is not set.
    pub fn get_or<T: FromParam>(&self, key: &str, default: T) -> Result<T, ParamError> {
        match self.get(key)? {
            Some(v) => Ok(v),
            None => {
                self.recorded(key, &default);
                Ok(default)
            }
        }
    }

    /// The value of `key` as `T`; an error naming the key when it is not set.
    pub fn require<T: FromParam>(&self, key: &str) -> Result<T, ParamError> {
        self.get(key)?.ok_or_else(|| ParamError::Missing {
            key: key.to_owned(),
            expected: T::EXPECTED,
            node: self.node.clone(),
        })
    }

    /// Applies the sections of a params file that match this node, in file order.
    pub fn apply_params_file(&mut self, path: &Path) -> Result<(), ParamError> {
        let text = std::fs::read_to_string(path).map_err(|source| ParamError::Read {
            path: path.to_owned(),
            source,
        })?;
        self.apply_params_yaml(&text, path)
    }

    /// Applies params-file text (`path` only names it in errors and sources).
    pub fn apply_params_yaml(&mut self, text: &str, path: &Path) -> Result<(), ParamError> {
        let file_err = |message: String| ParamError::File {
            path: path.to_owned(),
            message,
        };
        let doc: Value =
            serde_yaml::from_str(text).map_err(|e| file_err(format!("not valid YAML: {e}")))?;
        let Value::Mapping(top) = doc else {
            return Err(file_err(
                "the top level must map node names to `ros__parameters:` (e.g. `/**: {ros__parameters: {rate: 10}}`)"
                    .to_owned(),
            ));
        };
        let mut sections = Vec::new();
        collect_sections(&top, "", &mut sections).map_err(file_err)?;
        if sections.is_empty() {
            return Err(file_err("no `ros__parameters:` section found".to_owned()));
        }
        for (pattern, params) in sections {
            if !node_pattern_matches(&pattern, &self.node) {
                continue;
            }
            let mut flat = Vec::new();
            flatten(params, "", &mut flat)
                .map_err(|m| file_err(format!("section `{pattern}`: {m}")))?;
            for (key, value) in flat {
                let value = ParamValue::from_yaml(value).map_err(|m| {
                    file_err(format!("section `{pattern}`, parameter `{key}`: {m}"))
                })?;
                let source = ParamSource::ParamsFile {
                    path: path.to_owned(),
                    section: pattern.clone(),
                };
                self.set(&key, value, source);
            }
        }
        Ok(())
    }
}

/// Finds every `ros__parameters` mapping, with the node pattern made of the keys above it
/// (`/ns: {node: {ros__parameters: …}}` gives `/ns/node`).
fn collect_sections<'a>(
    map: &'a serde_yaml::Mapping,
    prefix: &str,
    out: &mut Vec<(String, &'a serde_yaml::Mapping)>,
) -> Result<(), String> {
    for (k, v) in map {
        let Some(key) = k.as_str() else {
            return Err(format!("node name {k:?} is not a string"));
        };
        if key == "ros__parameters" {
            let Value::Mapping(params) = v else {
                return Err(format!(
                    "`ros__parameters` under `{prefix}` is not a mapping"
                ));
            };
            let pattern = if prefix.is_empty() {
                "/".to_owned()
            } else {
                prefix.to_owned()
            };
            out.push((pattern, params));
            continue;
        }
        let Value::Mapping(inner) = v else {
            return Err(format!(
                "`{key}` holds a value but is not under `ros__parameters:`; write `{key}: {{ros__parameters: {{...}}}}`"
            ));
        };
        let name = key.trim_matches('/');
        let path = format!("{}/{}", prefix.trim_end_matches('/'), name);
        collect_sections(inner, &path, out)?;
    }
    Ok(())
}

fn flatten<'a>(
    map: &'a serde_yaml::Mapping,
    prefix: &str,
    out: &mut Vec<(String, &'a Value)>,
) -> Result<(), String> {
    for (k, v) in map {
        let key = match k {
            Value::String(s) => s.clone(),
            Value::Number(n) => n.to_string(),
            Value::Bool(b) => b.to_string(),
            other => return Err(format!("parameter name {other:?} is not a string")),
        };
        let full = if prefix.is_empty() {
            key
        } else {
            format!("{prefix}.{key}")
        };
        match v {
            Value::Mapping(inner) => flatten(inner, &full, out)?,
            _ => out.push((full, v)),
        }
    }
    Ok(())
}

/// Whether a params-file node pattern (`/**`, `/ns/*`, `recorder`, `/ns/recorder`) matches a
/// fully qualified node name. A pattern without a leading `/` is taken from the root.
pub fn node_pattern_matches(pattern: &str, node_fqn: &str) -> bool {
    let pat: Vec<&str> = pattern.split('/').filter(|t| !t.is_empty()).collect();
    let name: Vec<&str> = node_fqn.split('/').filter(|t| !t.is_empty()).collect();
    glob(&pat, &name)
}

fn glob(pat: &[&str], name: &[&str]) -> bool {
    match pat.split_first() {
        None => name.is_empty(),
        Some((&"**", rest)) => (0..=name.len()).any(|skip| glob(rest, &name[skip..])),
        Some((p, rest)) => match name.split_first() {
            Some((n, name_rest)) => (*p == "*" || p == n) && glob(rest, name_rest),
            None => false,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_line_values_are_yaml_typed() {
        assert_eq!(ParamValue::parse("100").unwrap(), ParamValue::Integer(100));
        assert_eq!(
            ParamValue::parse("100.0").unwrap(),
            ParamValue::Double(100.0)
        );
        assert_eq!(
            ParamValue::parse("-2.5e-3").unwrap(),
            ParamValue::Double(-2.5e-3)
        );
        assert_eq!(ParamValue::parse("true").unwrap(), ParamValue::Bool(true));
        assert_eq!(
            ParamValue::parse("world").unwrap(),
            ParamValue::String("world".into())
        );
        assert_eq!(
            ParamValue::parse("'42'").unwrap(),
            ParamValue::String("42".into())
        );
        assert_eq!(
            ParamValue::parse("[1, 2]").unwrap(),
            ParamValue::IntegerArray(vec![1, 2])
        );
        assert_eq!(
            ParamValue::parse("[1, 2.5]").unwrap(),
            ParamValue::DoubleArray(vec![1.0, 2.5])
        );
        assert_eq!(
            ParamValue::parse("[a, b]").unwrap(),
            ParamValue::StringArray(vec!["a".into(), "b".into()])
        );
        assert!(ParamValue::parse("[1, a]").is_err());
        assert_eq!(
            ParamValue::parse("").unwrap(),
            ParamValue::String(String::new())
        );
        assert!(ParamValue::parse("18446744073709551615").is_err());
    }

    #[test]
    fn typed_access_with_defaults_and_errors_naming_key_type_and_source() {
        let mut p = Parameters::new("/mppi");
        p.set(
            "rate",
            ParamValue::String("fast".into()),
            ParamSource::CommandLine,
        );
        p.set("samples", ParamValue::Integer(-3), ParamSource::CommandLine);
        p.set("horizon", ParamValue::Integer(20), ParamSource::Code);
        assert_eq!(p.get_or("horizon", 5usize).unwrap(), 20);
        assert_eq!(p.get_or("dt", 0.1f64).unwrap(), 0.1);
        assert_eq!(p.get::<f64>("horizon").unwrap(), Some(20.0));
        let err = p.get::<f64>("rate").unwrap_err().to_string();
        assert!(
            err.contains("`rate`") && err.contains("a double") && err.contains("string"),
            "{err}"
        );
        assert!(err.contains("command line"), "{err}");
        let err = p.get::<usize>("samples").unwrap_err();
        assert!(matches!(err, ParamError::OutOfRange { .. }), "{err}");
        let err = p.require::<String>("model").unwrap_err().to_string();
        assert!(
            err.contains("`model`") && err.contains("/mppi") && err.contains("a string"),
            "{err}"
        );
    }

    #[test]
    fn params_file_sections_match_node_names_and_flatten_keys() {
        let yaml = r#"
/**:
  ros__parameters:
    use_sim_time: true
    rate: 50
recorder:
  ros__parameters:
    rate: 100.0
    storage:
      chunk_size: 1024
      compression: {mode: none}
/other:
  ros__parameters:
    rate: 1
/robots:
  recorder:
    ros__parameters:
      nested_ns: true
"#;
        let mut p = Parameters::new("/recorder");
        p.apply_params_yaml(yaml, Path::new("p.yaml")).unwrap();
        assert_eq!(p.get::<bool>("use_sim_time").unwrap(), Some(true));
        assert_eq!(p.get::<f64>("rate").unwrap(), Some(100.0));
        assert_eq!(p.get::<i64>("storage.chunk_size").unwrap(), Some(1024));
        assert_eq!(
            p.get::<String>("storage.compression.mode")
                .unwrap()
                .as_deref(),
            Some("none")
        );
        assert_eq!(p.get::<bool>("nested_ns").unwrap(), None);
        match &p.entry("rate").unwrap().source {
            ParamSource::ParamsFile { section, .. } => assert_eq!(section, "/recorder"),
            other => panic!("{other:?}"),
        }
        let mut q = Parameters::new("/robots/recorder");
        q.apply_params_yaml(yaml, Path::new("p.yaml")).unwrap();
        assert_eq!(q.get::<bool>("nested_ns").unwrap(), Some(true));
        assert_eq!(q.get::<i64>("rate").unwrap(), Some(50));
    }

    #[test]
    fn params_file_errors_name_the_file() {
        let mut p = Parameters::new("/n");
        let err = p
            .apply_params_yaml("n:\n  rate: 1\n", Path::new("bad.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("bad.yaml") && err.contains("ros__parameters"),
            "{err}"
        );
        let err = p
            .apply_params_yaml("[1, 2]", Path::new("bad.yaml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("top level"), "{err}");
        let err = p
            .apply_params_yaml("n: {ros__parameters: {a: [1, x]}}", Path::new("b.yaml"))
            .unwrap_err();
        assert!(err.to_string().contains("`a`"), "{err}");
        let err = p
            .apply_params_file(Path::new("/nonexistent/x.yaml"))
            .unwrap_err();
        assert!(matches!(err, ParamError::Read { .. }));
    }

    #[test]
    fn node_patterns_with_wildcards() {
        assert!(node_pattern_matches("/**", "/a/b/n"));
        assert!(node_pattern_matches("/**", "/n"));
        assert!(node_pattern_matches("n", "/n"));
        assert!(!node_pattern_matches("n", "/a/n"));
        assert!(node_pattern_matches("/a/*", "/a/n"));
        assert!(!node_pattern_matches("/a/*", "/a/b/n"));
        assert!(node_pattern_matches("/**/n", "/a/b/n"));
        assert!(node_pattern_matches("/**/n", "/n"));
        assert!(!node_pattern_matches("/**/n", "/a/m"));
    }
}
