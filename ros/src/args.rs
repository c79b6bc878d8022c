//! The ROS 2 command line: our own arguments are separated from the `--ros-args … [--]` sections,
//! which hold remaps (`-r from:=to`, `-r __node:=name`, `-r __ns:=/ns`, `-r node:from:=to`),
//! parameters (`-p name:=value`, `--params-file FILE`) and `--log-level`.

use std::path::PathBuf;

use crate::names::{self, NameError};
use crate::params::{ParamError, ParamSource, ParamValue, Parameters};

/// A remap rule `[node:]from:=to`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Remap {
    /// Only for the node of this name, if given.
    pub node: Option<String>,
    /// The name to replace (expanded before comparing).
    pub from: String,
    /// The replacement.
    pub to: String,
}

/// One parameter source on the command line, in order of appearance.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamArg {
    /// `-p name:=value`.
    Value {
        /// The parameter name.
        name: String,
        /// The YAML-typed value.
        value: ParamValue,
    },
    /// `--params-file FILE`.
    File(PathBuf),
}

/// Severity threshold from `--log-level`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum LogLevel {
    /// `debug`.
    Debug,
    /// `info`.
    Info,
    /// `warn`.
    Warn,
    /// `error`.
    Error,
    /// `fatal` (shown as errors).
    Fatal,
}

impl LogLevel {
    /// Parses a ROS 2 severity name (any case).
    pub fn parse(text: &str) -> Option<LogLevel> {
        match text.to_ascii_lowercase().as_str() {
            "debug" => Some(LogLevel::Debug),
            "info" => Some(LogLevel::Info),
            "warn" | "warning" => Some(LogLevel::Warn),
            "error" => Some(LogLevel::Error),
            "fatal" => Some(LogLevel::Fatal),
            _ => None,
        }
    }

    /// The `tracing` filter directive for this level.
    pub fn directive(self) -> &'static str {
        match self {
            LogLevel::Debug => "debug",
            LogLevel::Info => "info",
            LogLevel::Warn => "warn",
            LogLevel::Error | LogLevel::Fatal => "error",
        }
    }
}

/// Errors on the command line.
#[derive(Debug, thiserror::Error)]
pub enum ArgsError {
    /// A flag that needs a value was last.
    #[error("`{0}` needs a value after it")]
    MissingValue(String),
    /// A remap rule without `:=`.
    #[error("remap rule `{0}` is not of the form `from:=to` (e.g. `-r /car/pose:=/mocap/pose`)")]
    BadRemap(String),
    /// A parameter assignment without `:=`.
    #[error("parameter `{0}` is not of the form `name:=value` (e.g. `-p rate:=100.0`)")]
    BadParam(String),
    /// A parameter value that is not a ROS 2 parameter.
    #[error("parameter `{name}`: {message}")]
    BadParamValue {
        /// The parameter name.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// A `--log-level` that is not a severity.
    #[error("log level `{0}` is not one of debug, info, warn, error, fatal")]
    BadLogLevel(String),
    /// An unknown argument inside `--ros-args`.
    #[error(
        "unknown ROS argument `{0}`: inside `--ros-args` use -r/--remap, -p/--param, --params-file, \
         --log-level, or end the section with `--`"
    )]
    UnknownRosArg(String),
    /// A bad node name or namespace in `__node:=` / `__ns:=`.
    #[error(transparent)]
    Name(#[from] NameError),
}

/// A node's command line, split into our own arguments and the ROS arguments.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NodeArgs {
    /// Arguments outside `--ros-args` sections, for the node's own parser.
    pub program_args: Vec<String>,
    /// Topic remap rules, in order.
    pub remaps: Vec<Remap>,
    /// `__node:=` (node-specific rules are kept in `remaps` and resolved by [`Self::node_name`]).
    pub node_name: Option<String>,
    /// `__ns:=`.
    pub namespace: Option<String>,
    /// Parameter sources in command-line order.
    pub params: Vec<ParamArg>,
    /// `--log-level LEVEL`.
    pub log_level: Option<LogLevel>,
}

impl NodeArgs {
    /// Parses `std::env::args()` without the program name.
    pub fn from_env() -> Result<NodeArgs, ArgsError> {
        NodeArgs::parse(std::env::args().skip(1))
    }

    /// Parses arguments (without the program name).
    pub fn parse<I, S>(args: I) -> Result<NodeArgs, ArgsError>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let mut out = NodeArgs::default();
        let mut it = args.into_iter().map(Into::into);
        let mut in_ros = false;
        while let Some(arg) = it.next() {
            if !in_ros {
                if arg == "--ros-args" {
                    in_ros = true;
                } else {
                    out.program_args.push(arg);
                }
                continue;
            }
            let mut value = |flag: &str| {
                it.next()
                    .ok_or_else(|| ArgsError::MissingValue(flag.to_owned()))
            };
            match arg.as_str() {
                "--" => in_ros = false,
                "--ros-args" => {}
                "-r" | "--remap" => {
                    let rule = value(&arg)?;
                    out.add_remap(&rule)?;
                }
                "-p" | "--param" => {
                    let assignment = value(&arg)?;
                    let (name, text) = assignment
                        .split_once(":=")
                        .ok_or_else(|| ArgsError::BadParam(assignment.clone()))?;
                    if name.is_empty() {
                        return Err(ArgsError::BadParam(assignment.clone()));
                    }
                    let value =
                        ParamValue::parse(text).map_err(|message| ArgsError::BadParamValue {
                            name: name.to_owned(),
                            message,
                        })?;
                    out.params.push(ParamArg::Value {
                        name: name.to_owned(),
                        value,
                    });
                }
                "--params-file" => out.params.push(ParamArg::File(PathBuf::from(value(&arg)?))),
                "--log-level" => {
                    let level = value(&arg)?;
                    // `logger_name:=level` sets one logger; we only honour the global level.
                    match level.split_once(":=") {
                        Some(_) => {}
                        None => {
                            out.log_level = Some(
                                LogLevel::parse(&level)
                                    .ok_or_else(|| ArgsError::BadLogLevel(level.clone()))?,
                            );
                        }
                    }
                }
                // Accepted for compatibility with ROS 2 launch files; they do not apply here.
                "-e" | "--enclave" | "--log-config-file" | "--log-file-name" => {
                    value(&arg)?;
                }
                "--enable-rosout-logs"
                | "--disable-rosout-logs"
                | "--enable-stdout-logs"
                | "--disable-stdout-logs"
                | "--enable-external-lib-logs"
                | "--disable-external-lib-logs" => {}
                _ => return Err(ArgsError::UnknownRosArg(arg)),
            }
        }
        Ok(out)
    }

    fn add_remap(&mut self, rule: &str) -> Result<(), ArgsError> {
        let (lhs, to) = rule
            .split_once(":=")
            .ok_or_else(|| ArgsError::BadRemap(rule.to_owned()))?;
        let (node, from) = match lhs.split_once(':') {
            Some((node, from)) => (Some(node.to_owned()), from),
            None => (None, lhs),
        };
        if from.is_empty() || to.is_empty() {
            return Err(ArgsError::BadRemap(rule.to_owned()));
        }
        match from {
            "__node" | "__name" if node.is_none() => {
                names::validate_node_name(to)?;
                self.node_name = Some(to.to_owned());
            }
            "__ns" if node.is_none() => {
                self.namespace = Some(names::normalize_namespace(to)?);
            }
            _ => self.remaps.push(Remap {
                node,
                from: from.to_owned(),
                to: to.to_owned(),
            }),
        }
        Ok(())
    }

    /// The node's name: `__node:=` if given (also `default:__node:=name`), else `default`.
    pub fn node_name(&self, default: &str) -> String {
        let specific = self.remaps.iter().find(|r| {
            r.node.as_deref() == Some(default) && (r.from == "__node" || r.from == "__name")
        });
        match (specific, &self.node_name) {
            (Some(rule), _) => rule.to.clone(),
            (None, Some(name)) => name.clone(),
            (None, None) => default.to_owned(),
        }
    }

    /// The node's namespace: `__ns:=` if given, else `/`.
    pub fn namespace(&self) -> String {
        self.namespace.clone().unwrap_or_else(|| "/".to_owned())
    }

    /// The parameters for the node with this fully qualified name: params files and `-p`
    /// overrides applied in command-line order.
    pub fn parameters(&self, node_fqn: &str) -> Result<Parameters, ParamError> {
        let mut p = Parameters::new(node_fqn);
        for arg in &self.params {
            match arg {
                ParamArg::Value { name, value } => {
                    p.set(name, value.clone(), ParamSource::CommandLine)
                }
                ParamArg::File(path) => p.apply_params_file(path)?,
            }
        }
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn splits_program_args_from_ros_args() {
        let a = NodeArgs::parse([
            "-o",
            "bags/run1",
            "/car/pose",
            "--ros-args",
            "-r",
            "/car/pose:=/mocap/pose",
            "-p",
            "rate:=100",
            "--",
            "--all",
        ])
        .unwrap();
        assert_eq!(a.program_args, ["-o", "bags/run1", "/car/pose", "--all"]);
        assert_eq!(
            a.remaps,
            [Remap {
                node: None,
                from: "/car/pose".into(),
                to: "/mocap/pose".into()
            }]
        );
        assert_eq!(
            a.params,
            [ParamArg::Value {
                name: "rate".into(),
                value: ParamValue::Integer(100)
            }]
        );
    }

    #[test]
    fn node_name_namespace_and_node_specific_rules() {
        let a = NodeArgs::parse([
            "--ros-args",
            "-r",
            "__node:=rec2",
            "--remap",
            "__ns:=/robot1/",
            "-r",
            "player:/a:=/b",
            "--log-level",
            "WARN",
        ])
        .unwrap();
        assert_eq!(a.node_name("recorder"), "rec2");
        assert_eq!(a.namespace(), "/robot1");
        assert_eq!(
            a.remaps,
            [Remap {
                node: Some("player".into()),
                from: "/a".into(),
                to: "/b".into()
            }]
        );
        assert_eq!(a.log_level, Some(LogLevel::Warn));
        let b = NodeArgs::parse(["--ros-args", "-r", "recorder:__node:=r9"]).unwrap();
        assert_eq!(b.node_name("recorder"), "r9");
        assert_eq!(b.node_name("player"), "player");
        assert_eq!(b.namespace(), "/");
    }

    #[test]
    fn several_ros_args_sections_and_ignored_flags() {
        let a = NodeArgs::parse([
            "x",
            "--ros-args",
            "--disable-rosout-logs",
            "-e",
            "/enc",
            "--",
            "y",
            "--ros-args",
            "-p",
            "a:=b",
        ])
        .unwrap();
        assert_eq!(a.program_args, ["x", "y"]);
        assert_eq!(a.params.len(), 1);
    }

    #[test]
    fn bad_arguments_are_named() {
        let err = NodeArgs::parse(["--ros-args", "-r", "nocolon"]).unwrap_err();
        assert!(
            matches!(err, ArgsError::BadRemap(ref r) if r == "nocolon"),
            "{err}"
        );
        let err = NodeArgs::parse(["--ros-args", "-p", "rate=3"]).unwrap_err();
        assert!(matches!(err, ArgsError::BadParam(_)), "{err}");
        let err = NodeArgs::parse(["--ros-args", "-p"]).unwrap_err();
        assert!(
            matches!(err, ArgsError::MissingValue(ref f) if f == "-p"),
            "{err}"
        );
        let err = NodeArgs::parse(["--ros-args", "--bogus"]).unwrap_err();
        assert!(err.to_string().contains("--bogus"), "{err}");
        let err = NodeArgs::parse(["--ros-args", "--log-level", "loud"]).unwrap_err();
        assert!(matches!(err, ArgsError::BadLogLevel(_)));
        let err = NodeArgs::parse(["--ros-args", "-r", "__ns:=relative"]).unwrap_err();
        assert!(
            matches!(err, ArgsError::Name(NameError::RelativeNamespace(_))),
            "{err}"
        );
        let err = NodeArgs::parse(["--ros-args", "-r", "__node:=a/b"]).unwrap_err();
        assert!(matches!(err, ArgsError::Name(_)), "{err}");
        let err = NodeArgs::parse(["--ros-args", "-p", "l:=[1, x]"]).unwrap_err();
        assert!(matches!(err, ArgsError::BadParamValue { .. }), "{err}");
    }

    #[test]
    fn params_files_and_overrides_apply_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("params.yaml");
        let mut f = std::fs::File::create(&path).unwrap();
        writeln!(
            f,
            "/**:\n  ros__parameters:\n    rate: 10\n    frame: world"
        )
        .unwrap();
        drop(f);
        let p = path.to_str().unwrap();
        let a = NodeArgs::parse([
            "--ros-args",
            "-p",
            "rate:=5",
            "--params-file",
            p,
            "-p",
            "frame:=table",
        ])
        .unwrap();
        let params = a.parameters("/sim").unwrap();
        assert_eq!(params.get::<i64>("rate").unwrap(), Some(10)); // file after -p wins
        assert_eq!(
            params.get::<String>("frame").unwrap().as_deref(),
            Some("table")
        );
        assert!(matches!(
            params.entry("rate").unwrap().source,
            ParamSource::ParamsFile { .. }
        ));
        assert_eq!(
            params.entry("frame").unwrap().source,
            ParamSource::CommandLine
        );
    }
}
