//! ROS 2 names: validation, expansion of relative and private (`~`) names, remapping, and the
//! mapping of ROS topic and type names to their DDS form.
//!
//! The rules follow the ROS 2 design article "Topic and Service name mapping to DDS" and rcl's
//! remapping: a topic name is expanded against the node's namespace (`x` → `/ns/x`) and private
//! names against the node's fully qualified name (`~/x` → `/ns/node/x`); the `from` side of a
//! remap rule is expanded the same way before it is compared, and the first matching rule wins.
//! Type names map to DDS with `dynlab_msgs::ros_to_dds_type_name` and its inverse.

use crate::args::Remap;

/// Errors in a ROS 2 name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// The name is empty.
    #[error("empty {what} name: give a name such as `pose` or `/car/pose`")]
    Empty {
        /// What kind of name ("topic", "node", "namespace").
        what: &'static str,
    },
    /// A token holds a character other than `[A-Za-z0-9_]`.
    #[error(
        "{what} name `{name}` contains `{bad}`: ROS 2 names use letters, digits and `_` separated by `/`"
    )]
    BadChar {
        /// What kind of name.
        what: &'static str,
        /// The offending name.
        name: String,
        /// The character that is not allowed.
        bad: char,
    },
    /// A token starts with a digit.
    #[error(
        "{what} name `{name}` has a token starting with a digit: tokens must start with a letter or `_`"
    )]
    LeadingDigit {
        /// What kind of name.
        what: &'static str,
        /// The offending name.
        name: String,
    },
    /// Repeated or trailing `/`, or a repeated `_`.
    #[error("{what} name `{name}` has an empty token (`//` or a trailing `/`) or a repeated `__`")]
    BadSeparator {
        /// What kind of name.
        what: &'static str,
        /// The offending name.
        name: String,
    },
    /// `~` not followed by `/` or end of name.
    #[error("topic name `{0}`: `~` must stand alone or be followed by `/` (write `~/{rest}`)", rest = .0.trim_start_matches('~'))]
    BadTilde(String),
    /// A namespace that is not absolute.
    #[error("namespace `{0}` must be absolute (start with `/`)")]
    RelativeNamespace(String),
    /// A node name that contains `/`.
    #[error(
        "node name `{0}` must be a single token without `/`; put the path in the namespace (`-r __ns:=/path`)"
    )]
    NodeNameWithSlash(String),
    /// A type name not of the form `pkg/msg/Type`.
    #[error(
        "type name `{0}` is not of the form `package/msg/Type` (or the DDS form `package::msg::dds_::Type_`)"
    )]
    BadTypeName(String),
}

fn check_tokens(what: &'static str, name: &str, tokens: &str) -> Result<(), NameError> {
    for tok in tokens.split('/') {
        if tok.is_empty() || tok.contains("__") {
            return Err(NameError::BadSeparator {
                what,
                name: name.to_owned(),
            });
        }
        if let Some(bad) = tok
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '_'))
        {
            return Err(NameError::BadChar {
                what,
                name: name.to_owned(),
                bad,
            });
        }
        if tok.starts_with(|c: char| c.is_ascii_digit()) {
            return Err(NameError::LeadingDigit {
                what,
                name: name.to_owned(),
            });
        }
    }
    Ok(())
}

/// Checks a node name: a single token of `[A-Za-z0-9_]`, not starting with a digit.
pub fn validate_node_name(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty { what: "node" });
    }
    if name.contains('/') {
        return Err(NameError::NodeNameWithSlash(name.to_owned()));
    }
    check_tokens("node", name, name)
}

/// Checks a namespace and returns it normalised (absolute, no trailing `/`, `/` for the root).
pub fn normalize_namespace(ns: &str) -> Result<String, NameError> {
    if ns.is_empty() || ns == "/" {
        return Ok("/".to_owned());
    }
    let Some(rest) = ns.strip_prefix('/') else {
        return Err(NameError::RelativeNamespace(ns.to_owned()));
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    check_tokens("namespace", ns, rest)?;
    Ok(format!("/{rest}"))
}

/// Joins a namespace and a relative name (`/` + `a` → `/a`, `/ns` + `a/b` → `/ns/a/b`).
fn join(ns: &str, rel: &str) -> String {
    if ns == "/" {
        format!("/{rel}")
    } else {
        format!("{ns}/{rel}")
    }
}

/// Expands a topic name to its fully qualified form for a node called `node` in namespace `ns`
/// (already normalised): `/x` stays, `x` → `/ns/x`, `~` → `/ns/node`, `~/x` → `/ns/node/x`;
/// the substitutions `{node}` and `{ns}` (or `{namespace}`) are replaced first.
pub fn expand_topic_name(name: &str, node: &str, ns: &str) -> Result<String, NameError> {
    if name.is_empty() {
        return Err(NameError::Empty { what: "topic" });
    }
    let ns_body = ns.trim_start_matches('/');
    let substituted = name
        .replace("{node}", node)
        .replace("{namespace}", ns_body)
        .replace("{ns}", ns_body);
    let private = join(ns, node);
    let full = if substituted == "~" {
        private
    } else if let Some(rest) = substituted.strip_prefix("~/") {
        join(&private, rest)
    } else if substituted.starts_with('~') {
        return Err(NameError::BadTilde(name.to_owned()));
    } else if substituted.starts_with('/') {
        substituted
    } else {
        join(ns, &substituted)
    };
    let body = full.strip_prefix('/').unwrap_or(&full);
    if body.is_empty() {
        return Err(NameError::Empty { what: "topic" });
    }
    check_tokens("topic", name, body)?;
    Ok(full)
}

/// Resolves a topic name as rcl does: expands it, then applies the first remap rule whose
/// expanded `from` equals it (node-specific rules only for the node they name). Returns the
/// fully qualified ROS name, e.g. `/car/pose`.
pub fn resolve_topic_name(
    name: &str,
    node: &str,
    ns: &str,
    remaps: &[Remap],
) -> Result<String, NameError> {
    let expanded = expand_topic_name(name, node, ns)?;
    for rule in remaps {
        if rule.from.starts_with("__") {
            continue;
        }
        if let Some(target) = &rule.node
            && target != node
        {
            continue;
        }
        if expand_topic_name(&rule.from, node, ns)? == expanded {
            return expand_topic_name(&rule.to, node, ns);
        }
    }
    Ok(expanded)
}

/// The DDS topic name of a ROS topic: `rt` followed by the fully qualified name
/// (`/car/pose` → `rt/car/pose`).
pub fn dds_topic_name(fully_qualified: &str) -> String {
    format!("rt{fully_qualified}")
}

/// The ROS topic name of a DDS topic carrying ROS messages (`rt/car/pose` → `/car/pose`), or
/// `None` for DDS topics that are not ROS topics (services, DDS built-ins, `ros_discovery_info`).
pub fn ros_topic_name(dds_name: &str) -> Option<String> {
    dds_name.strip_prefix("rt/").map(|rest| format!("/{rest}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn remap(from: &str, to: &str) -> Remap {
        Remap {
            node: None,
            from: from.into(),
            to: to.into(),
        }
    }

    #[test]
    fn expands_relative_absolute_and_private_names() {
        assert_eq!(
            expand_topic_name("/car/pose", "rec", "/ns").unwrap(),
            "/car/pose"
        );
        assert_eq!(expand_topic_name("pose", "rec", "/").unwrap(), "/pose");
        assert_eq!(
            expand_topic_name("car/pose", "rec", "/robot1").unwrap(),
            "/robot1/car/pose"
        );
        assert_eq!(
            expand_topic_name("~", "rec", "/robot1").unwrap(),
            "/robot1/rec"
        );
        assert_eq!(
            expand_topic_name("~/status", "rec", "/").unwrap(),
            "/rec/status"
        );
        assert_eq!(
            expand_topic_name("{node}/out", "rec", "/a/b").unwrap(),
            "/a/b/rec/out"
        );
        assert_eq!(expand_topic_name("/{ns}/x", "rec", "/a").unwrap(), "/a/x");
    }

    #[test]
    fn rejects_bad_topic_names() {
        assert!(matches!(
            expand_topic_name("", "n", "/"),
            Err(NameError::Empty { .. })
        ));
        assert!(matches!(
            expand_topic_name("a//b", "n", "/"),
            Err(NameError::BadSeparator { .. })
        ));
        assert!(matches!(
            expand_topic_name("a/", "n", "/"),
            Err(NameError::BadSeparator { .. })
        ));
        assert!(matches!(
            expand_topic_name("a__b", "n", "/"),
            Err(NameError::BadSeparator { .. })
        ));
        assert!(matches!(
            expand_topic_name("a-b", "n", "/"),
            Err(NameError::BadChar { bad: '-', .. })
        ));
        assert!(matches!(
            expand_topic_name("9lives", "n", "/"),
            Err(NameError::LeadingDigit { .. })
        ));
        assert!(matches!(
            expand_topic_name("~foo", "n", "/"),
            Err(NameError::BadTilde(_))
        ));
        assert!(matches!(
            expand_topic_name("/", "n", "/"),
            Err(NameError::Empty { .. })
        ));
    }

    #[test]
    fn namespaces_and_node_names_are_checked() {
        assert_eq!(normalize_namespace("").unwrap(), "/");
        assert_eq!(normalize_namespace("/robot1/").unwrap(), "/robot1");
        assert_eq!(normalize_namespace("/a/b").unwrap(), "/a/b");
        assert!(matches!(
            normalize_namespace("robot1"),
            Err(NameError::RelativeNamespace(_))
        ));
        assert!(validate_node_name("recorder_2").is_ok());
        assert!(matches!(
            validate_node_name("a/b"),
            Err(NameError::NodeNameWithSlash(_))
        ));
        assert!(validate_node_name("2fast").is_err());
    }

    #[test]
    fn remapping_matches_expanded_names_and_first_rule_wins() {
        let rules = [
            remap("pose", "/mocap/rc_car/pose"),
            remap("/car/pose", "/never"),
            remap("/car/cmd", "cmd_remapped"),
        ];
        // relative `from` is expanded with the node's namespace before comparing
        assert_eq!(
            resolve_topic_name("/car/pose", "n", "/car", &rules).unwrap(),
            "/mocap/rc_car/pose"
        );
        assert_eq!(
            resolve_topic_name("pose", "n", "/car", &rules).unwrap(),
            "/mocap/rc_car/pose"
        );
        // relative `to` is expanded too
        assert_eq!(
            resolve_topic_name("/car/cmd", "n", "/ns", &rules).unwrap(),
            "/ns/cmd_remapped"
        );
        // unmatched names pass through expanded
        assert_eq!(
            resolve_topic_name("other", "n", "/ns", &rules).unwrap(),
            "/ns/other"
        );
    }

    #[test]
    fn node_specific_rules_only_apply_to_their_node() {
        let rules = [Remap {
            node: Some("player".into()),
            from: "/a".into(),
            to: "/b".into(),
        }];
        assert_eq!(
            resolve_topic_name("/a", "player", "/", &rules).unwrap(),
            "/b"
        );
        assert_eq!(
            resolve_topic_name("/a", "recorder", "/", &rules).unwrap(),
            "/a"
        );
    }

    #[test]
    fn private_names_remap() {
        let rules = [remap("~/out", "/global_out")];
        assert_eq!(
            resolve_topic_name("~/out", "n", "/ns", &rules).unwrap(),
            "/global_out"
        );
        assert_eq!(
            resolve_topic_name("/ns/n/out", "n", "/ns", &rules).unwrap(),
            "/global_out"
        );
    }

    #[test]
    fn dds_names_round_trip() {
        assert_eq!(dds_topic_name("/car/pose"), "rt/car/pose");
        assert_eq!(ros_topic_name("rt/car/pose").as_deref(), Some("/car/pose"));
        assert_eq!(ros_topic_name("rq/get_parametersRequest"), None);
        assert_eq!(ros_topic_name("ros_discovery_info"), None);
    }
}
