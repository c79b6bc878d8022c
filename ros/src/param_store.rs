//! The parameters a node offers over the ROS 2 parameter services: declared values with their
//! descriptors (description, read-only flag, numeric range), and the rules a remote set must pass.
//!
//! This is the pure part of the parameter services (no DDS): `ros2 param list/get/set/describe`
//! are answered from a [`ParamStore`], and the service thread in [`crate::param_services`] only
//! moves requests and replies. A set is checked completely before anything changes:
//!
//! - the parameter must be declared (`parameter 'x' is not declared by /node`);
//! - a read-only parameter is refused with `read-only: restart the node with -p name:=value`;
//! - the type must be the declared one; an integer is accepted for a double parameter (`ros2
//!   param set /n tol 1` sends an integer) and stored as a double;
//! - a number must lie in the declared range (both ends included; a `step` other than 0 also
//!   requires `from + k·step`, as rclcpp checks it).
//!
//! Accepted sets come back as [`ParamChange`]s, which the node loop receives through
//! [`crate::Node::poll_parameter_changes`].

use std::collections::BTreeMap;

use crate::params::ParamValue;

/// The numeric range of a parameter (ROS 2 `IntegerRange` / `FloatingPointRange`).
#[derive(Debug, Clone, PartialEq)]
pub enum ParamRange {
    /// Integers from `from` to `to` (both included); `step` 0 means any integer between.
    Integer {
        /// Lowest value.
        from: i64,
        /// Highest value.
        to: i64,
        /// Spacing of allowed values from `from` (0: none).
        step: i64,
    },
    /// Doubles from `from` to `to` (both included); `step` 0 means any value between.
    Double {
        /// Lowest value.
        from: f64,
        /// Highest value.
        to: f64,
        /// Spacing of allowed values from `from` (0: continuous).
        step: f64,
    },
}

impl ParamRange {
    /// Checks a value against the range; the reason names the range when it fails.
    fn check(&self, value: &ParamValue) -> Result<(), String> {
        match (self, value) {
            (ParamRange::Integer { from, to, step }, ParamValue::Integer(v)) => {
                if v < from || v > to {
                    return Err(format!("{v} is outside the range [{from}, {to}]"));
                }
                if *step > 0 && (v - from) % step != 0 && v != to {
                    return Err(format!("{v} is not {from} + k·{step} (k integer)"));
                }
                Ok(())
            }
            (ParamRange::Double { from, to, step }, ParamValue::Double(v)) => {
                if !v.is_finite() {
                    return Err(format!("{v} is not a finite number"));
                }
                if v < from || v > to {
                    return Err(format!("{v} is outside the range [{from}, {to}]"));
                }
                if *step > 0.0 && v != to {
                    let k = ((v - from) / step).round();
                    if (from + k * step - v).abs() > 1e-9 * step.abs().max(v.abs()) {
                        return Err(format!("{v} is not {from} + k·{step} (k integer)"));
                    }
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

/// What a parameter is and how it may change.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamDescriptor {
    /// One line for `ros2 param describe`.
    pub description: String,
    /// Further constraints in words (e.g. `"x,y,θ in m, m, rad"`).
    pub additional_constraints: String,
    /// `true`: fixed at start (a set is refused: restart the node with `-p name:=value`).
    pub read_only: bool,
    /// Allowed numeric values, if limited.
    pub range: Option<ParamRange>,
}

impl ParamDescriptor {
    /// A parameter fixed at start.
    pub fn read_only(description: impl Into<String>) -> Self {
        Self {
            description: description.into(),
            additional_constraints: String::new(),
            read_only: true,
            range: None,
        }
    }

    /// A parameter that can change while the node runs.
    pub fn dynamic(description: impl Into<String>) -> Self {
        Self {
            read_only: false,
            ..Self::read_only(description)
        }
    }

    /// With a double range `[from, to]` (continuous).
    pub fn range(mut self, from: f64, to: f64) -> Self {
        self.range = Some(ParamRange::Double {
            from,
            to,
            step: 0.0,
        });
        self
    }

    /// With an integer range `[from, to]` (every integer between).
    pub fn integer_range(mut self, from: i64, to: i64) -> Self {
        self.range = Some(ParamRange::Integer { from, to, step: 0 });
        self
    }

    /// With a constraint in words.
    pub fn constraints(mut self, text: impl Into<String>) -> Self {
        self.additional_constraints = text.into();
        self
    }
}

/// A declared parameter: its current value and descriptor.
#[derive(Debug, Clone, PartialEq)]
pub struct Declared {
    /// The current value.
    pub value: ParamValue,
    /// The descriptor.
    pub descriptor: ParamDescriptor,
}

/// An accepted change of a parameter, for the node loop and `/parameter_events`.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamChange {
    /// The parameter's name.
    pub name: String,
    /// Its new value (of the declared type).
    pub value: ParamValue,
}

/// "a double", "an integer".
fn article(type_name: &str) -> String {
    if type_name.starts_with(['a', 'e', 'i', 'o', 'u']) {
        format!("an {type_name}")
    } else {
        format!("a {type_name}")
    }
}

/// The reason a set is refused for a read-only parameter.
pub fn read_only_reason(name: &str) -> String {
    format!("read-only: restart the node with -p {name}:=value to change `{name}`")
}

/// A node's own check of a new value (beyond type and range), e.g. the format of a string;
/// `Err` carries the reason the set is refused with.
pub type ParamCheck = fn(&ParamValue) -> Result<(), String>;

/// The declared parameters of one node.
#[derive(Debug, Clone, Default)]
pub struct ParamStore {
    node: String,
    params: BTreeMap<String, Declared>,
    checks: BTreeMap<String, ParamCheck>,
}

impl ParamStore {
    /// An empty store for the node with this fully qualified name.
    pub fn new(node_fqn: &str) -> Self {
        Self {
            node: node_fqn.to_owned(),
            params: BTreeMap::new(),
            checks: BTreeMap::new(),
        }
    }

    /// The node's fully qualified name.
    pub fn node(&self) -> &str {
        &self.node
    }

    /// Declares (or re-declares) a parameter with its current value. The value must fit the
    /// descriptor's range; an integer for a double range is stored as a double.
    pub fn declare(
        &mut self,
        name: &str,
        value: ParamValue,
        descriptor: ParamDescriptor,
    ) -> Result<(), String> {
        let value = match (&descriptor.range, value) {
            (Some(ParamRange::Double { .. }), ParamValue::Integer(i)) => {
                ParamValue::Double(i as f64)
            }
            (_, v) => v,
        };
        if let Some(range) = &descriptor.range {
            let fits = matches!(
                (range, &value),
                (ParamRange::Integer { .. }, ParamValue::Integer(_))
                    | (ParamRange::Double { .. }, ParamValue::Double(_))
            );
            if !fits {
                return Err(format!(
                    "parameter `{name}`: a {} cannot have a {} range",
                    value.type_name(),
                    match range {
                        ParamRange::Integer { .. } => "integer",
                        ParamRange::Double { .. } => "double",
                    }
                ));
            }
            range
                .check(&value)
                .map_err(|r| format!("parameter `{name}`: {r}"))?;
        }
        self.params
            .insert(name.to_owned(), Declared { value, descriptor });
        Ok(())
    }

    /// Adds the node's own check for sets of `name` (run after the type and range checks).
    pub fn set_check(&mut self, name: &str, check: ParamCheck) {
        self.checks.insert(name.to_owned(), check);
    }

    /// Declares a read-only parameter unless one of that name exists (the node's value as read
    /// at start).
    pub fn declare_if_absent(&mut self, name: &str, value: ParamValue, description: &str) {
        if !self.params.contains_key(name) {
            self.params.insert(
                name.to_owned(),
                Declared {
                    value,
                    descriptor: ParamDescriptor::read_only(description),
                },
            );
        }
    }

    /// A declared parameter.
    pub fn get(&self, name: &str) -> Option<&Declared> {
        self.params.get(name)
    }

    /// Every declared name, sorted.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.params.keys().map(String::as_str)
    }

    /// Checks a new value for a parameter; returns the value to store (an integer for a double
    /// parameter becomes a double) or the reason it is refused.
    pub fn check(&self, name: &str, value: &ParamValue) -> Result<ParamValue, String> {
        self.check_value(name, value, false)
    }

    /// Sets a parameter from the node's own code (e.g. `goal` when a goal arrives on a topic):
    /// the checks of a remote set except the read-only one. Returns the change to announce.
    pub fn update(&mut self, name: &str, value: &ParamValue) -> Result<ParamChange, String> {
        let value = self.check_value(name, value, true)?;
        self.store(name, value.clone());
        Ok(ParamChange {
            name: name.to_owned(),
            value,
        })
    }

    fn check_value(
        &self,
        name: &str,
        value: &ParamValue,
        by_node: bool,
    ) -> Result<ParamValue, String> {
        let Some(d) = self.params.get(name) else {
            return Err(format!(
                "parameter `{name}` is not declared by {} (ros2 param list {} shows the declared ones)",
                self.node, self.node
            ));
        };
        if d.descriptor.read_only && !by_node {
            return Err(read_only_reason(name));
        }
        let value = match (&d.value, value) {
            (ParamValue::Double(_), ParamValue::Integer(i)) => ParamValue::Double(*i as f64),
            (_, v) => v.clone(),
        };
        if std::mem::discriminant(&value) != std::mem::discriminant(&d.value) {
            return Err(format!(
                "wrong type: `{name}` is {}, got {} ({value}); set e.g. {name} {}",
                article(d.value.type_name()),
                article(value.type_name()),
                d.value
            ));
        }
        if let Some(range) = &d.descriptor.range {
            range.check(&value).map_err(|r| format!("`{name}`: {r}"))?;
        }
        if let Some(check) = self.checks.get(name) {
            check(&value).map_err(|r| format!("`{name}`: {r}"))?;
        }
        Ok(value)
    }

    /// Sets each parameter on its own (ROS 2 `SetParameters`): one result per request entry, in
    /// order. Refused entries leave their parameter unchanged.
    pub fn set_each(
        &mut self,
        request: &[(String, ParamValue)],
    ) -> Vec<Result<ParamChange, String>> {
        request
            .iter()
            .map(|(name, value)| {
                let value = self.check(name, value)?;
                self.store(name, value.clone());
                Ok(ParamChange {
                    name: name.clone(),
                    value,
                })
            })
            .collect()
    }

    /// Sets all or none (ROS 2 `SetParametersAtomically`): the first refusal is the reason, and
    /// then nothing changes.
    pub fn set_all(
        &mut self,
        request: &[(String, ParamValue)],
    ) -> Result<Vec<ParamChange>, String> {
        let mut checked = Vec::with_capacity(request.len());
        for (name, value) in request {
            let value = self.check(name, value)?;
            checked.push(ParamChange {
                name: name.clone(),
                value,
            });
        }
        for c in &checked {
            self.store(&c.name, c.value.clone());
        }
        Ok(checked)
    }

    fn store(&mut self, name: &str, value: ParamValue) {
        if let Some(d) = self.params.get_mut(name) {
            d.value = value;
        }
    }

    /// ROS 2 `ListParameters`, with rclcpp's rules: without prefixes, names with fewer than
    /// `depth` dots (`depth` 0: all); with prefixes, names equal to a prefix or below `prefix.`
    /// within `depth` further levels. Returns the names and their distinct namespaces.
    pub fn list(&self, prefixes: &[String], depth: u64) -> (Vec<String>, Vec<String>) {
        let within = |dots: usize| depth == 0 || (dots as u64) < depth;
        let mut names = Vec::new();
        let mut spaces: Vec<String> = Vec::new();
        for name in self.params.keys() {
            let all = prefixes.is_empty() && within(name.matches('.').count());
            let under = prefixes.iter().any(|p| {
                name == p
                    || name
                        .strip_prefix(p.as_str())
                        .and_then(|rest| rest.strip_prefix('.'))
                        .is_some_and(|rest| within(rest.matches('.').count() + 1))
            });
            if all || under {
                names.push(name.clone());
                if let Some((space, _)) = name.rsplit_once('.')
                    && !spaces.iter().any(|s| s == space)
                {
                    spaces.push(space.to_owned());
                }
            }
        }
        (names, spaces)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn store() -> ParamStore {
        let mut s = ParamStore::new("/mppi_pusher");
        s.declare(
            "goal_tolerance",
            ParamValue::Double(0.02),
            ParamDescriptor::dynamic("goal reached within this xy distance [m]").range(0.0, 1.0),
        )
        .unwrap();
        s.declare(
            "samples",
            ParamValue::Integer(256),
            ParamDescriptor::read_only("MPPI samples K"),
        )
        .unwrap();
        s.declare(
            "horizon",
            ParamValue::Integer(8),
            ParamDescriptor::dynamic("steps").integer_range(1, 100),
        )
        .unwrap();
        s.declare(
            "goal",
            ParamValue::String(String::new()),
            ParamDescriptor::dynamic("x,y,θ"),
        )
        .unwrap();
        s
    }

    #[test]
    fn a_valid_set_changes_the_value_and_reports_the_change() {
        let mut s = store();
        let r = s.set_each(&[("goal_tolerance".into(), ParamValue::Double(0.05))]);
        assert_eq!(
            r,
            vec![Ok(ParamChange {
                name: "goal_tolerance".into(),
                value: ParamValue::Double(0.05)
            })]
        );
        assert_eq!(
            s.get("goal_tolerance").unwrap().value,
            ParamValue::Double(0.05)
        );
    }

    #[test]
    fn an_integer_for_a_double_parameter_is_stored_as_a_double() {
        let mut s = store();
        let r = s.set_each(&[("goal_tolerance".into(), ParamValue::Integer(1))]);
        assert_eq!(r[0].as_ref().unwrap().value, ParamValue::Double(1.0));
        assert_eq!(
            s.get("goal_tolerance").unwrap().value,
            ParamValue::Double(1.0)
        );
    }

    #[test]
    fn refusals_name_the_problem_and_leave_the_value() {
        let mut s = store();
        let cases = [
            (
                "samples",
                ParamValue::Integer(10),
                "read-only: restart the node with -p samples:=value",
            ),
            (
                "goal_tolerance",
                ParamValue::Double(1.5),
                "outside the range [0, 1]",
            ),
            (
                "goal_tolerance",
                ParamValue::Double(-0.1),
                "outside the range [0, 1]",
            ),
            (
                "goal_tolerance",
                ParamValue::Double(f64::NAN),
                "not a finite number",
            ),
            (
                "goal_tolerance",
                ParamValue::String("far".into()),
                "is a double, got a string",
            ),
            (
                "horizon",
                ParamValue::Double(2.0),
                "is an integer, got a double",
            ),
            (
                "horizon",
                ParamValue::Integer(0),
                "outside the range [1, 100]",
            ),
            (
                "nope",
                ParamValue::Integer(1),
                "`nope` is not declared by /mppi_pusher",
            ),
        ];
        for (name, value, reason) in cases {
            let before = s.get(name).cloned();
            let r = s.set_each(&[(name.into(), value.clone())]);
            let err = r[0].clone().unwrap_err();
            assert!(err.contains(reason), "{name} = {value}: {err}");
            assert_eq!(s.get(name).cloned(), before, "{name} changed");
        }
    }

    #[test]
    fn set_each_applies_the_valid_entries_and_set_all_none_when_one_fails() {
        let mut s = store();
        let req = vec![
            ("goal_tolerance".to_string(), ParamValue::Double(0.03)),
            ("samples".to_string(), ParamValue::Integer(9)),
        ];
        let r = s.set_each(&req);
        assert!(r[0].is_ok() && r[1].is_err());
        assert_eq!(
            s.get("goal_tolerance").unwrap().value,
            ParamValue::Double(0.03)
        );

        let req = vec![
            ("goal_tolerance".to_string(), ParamValue::Double(0.04)),
            ("horizon".to_string(), ParamValue::Integer(1000)),
        ];
        let err = s.set_all(&req).unwrap_err();
        assert!(err.contains("horizon") && err.contains("range"), "{err}");
        assert_eq!(
            s.get("goal_tolerance").unwrap().value,
            ParamValue::Double(0.03)
        );
        let ok = s
            .set_all(&[
                ("goal_tolerance".to_string(), ParamValue::Double(0.04)),
                ("horizon".to_string(), ParamValue::Integer(12)),
            ])
            .unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(s.get("horizon").unwrap().value, ParamValue::Integer(12));
    }

    #[test]
    fn a_node_check_refuses_with_its_reason() {
        let mut s = store();
        s.set_check("goal", |v| match v {
            ParamValue::String(t) if t.split(',').count() == 3 => Ok(()),
            _ => Err("give \"x,y,θ\"".to_owned()),
        });
        let r = s.set_each(&[("goal".into(), ParamValue::String("1,2".into()))]);
        assert_eq!(r[0].clone().unwrap_err(), "`goal`: give \"x,y,θ\"");
        assert_eq!(
            s.get("goal").unwrap().value,
            ParamValue::String(String::new())
        );
        let r = s.set_each(&[("goal".into(), ParamValue::String("1,2,0".into()))]);
        assert!(r[0].is_ok());
    }

    #[test]
    fn the_node_may_update_a_read_only_value_within_type_and_range() {
        let mut s = store();
        let c = s.update("samples", &ParamValue::Integer(512)).unwrap();
        assert_eq!(c.value, ParamValue::Integer(512));
        assert_eq!(s.get("samples").unwrap().value, ParamValue::Integer(512));
        assert!(
            s.update("goal_tolerance", &ParamValue::Double(3.0))
                .is_err()
        );
        assert!(s.update("samples", &ParamValue::Double(3.0)).is_err());
    }

    #[test]
    fn ranges_with_steps_follow_rclcpp() {
        let r = ParamRange::Integer {
            from: 0,
            to: 10,
            step: 4,
        };
        assert!(r.check(&ParamValue::Integer(8)).is_ok());
        assert!(
            r.check(&ParamValue::Integer(10)).is_ok(),
            "the upper end is always allowed"
        );
        assert!(r.check(&ParamValue::Integer(6)).is_err());
        let r = ParamRange::Double {
            from: 0.0,
            to: 1.0,
            step: 0.25,
        };
        assert!(r.check(&ParamValue::Double(0.75)).is_ok());
        assert!(r.check(&ParamValue::Double(0.3)).is_err());
    }

    #[test]
    fn declaring_checks_the_value_against_the_range() {
        let mut s = ParamStore::new("/n");
        let err = s
            .declare(
                "tol",
                ParamValue::Double(2.0),
                ParamDescriptor::dynamic("").range(0.0, 1.0),
            )
            .unwrap_err();
        assert!(err.contains("tol") && err.contains("outside"), "{err}");
        let err = s
            .declare(
                "name",
                ParamValue::String("a".into()),
                ParamDescriptor::dynamic("").range(0.0, 1.0),
            )
            .unwrap_err();
        assert!(err.contains("string cannot have a double range"), "{err}");
        s.declare(
            "tol",
            ParamValue::Integer(1),
            ParamDescriptor::dynamic("").range(0.0, 1.0),
        )
        .unwrap();
        assert_eq!(s.get("tol").unwrap().value, ParamValue::Double(1.0));
    }

    #[test]
    fn declare_if_absent_keeps_an_explicit_declaration() {
        let mut s = store();
        s.declare_if_absent("goal_tolerance", ParamValue::Double(9.0), "read at start");
        assert!(!s.get("goal_tolerance").unwrap().descriptor.read_only);
        s.declare_if_absent("rate", ParamValue::Double(100.0), "read at start");
        assert!(s.get("rate").unwrap().descriptor.read_only);
    }

    #[test]
    fn list_matches_rclcpp_prefix_and_depth_rules() {
        let mut s = ParamStore::new("/n");
        for n in ["a", "a.b", "a.b.c", "ab", "x.y"] {
            s.declare(n, ParamValue::Integer(0), ParamDescriptor::read_only(""))
                .unwrap();
        }
        let list = |p: &[&str], d| {
            let p: Vec<String> = p.iter().map(|s| s.to_string()).collect();
            s.list(&p, d)
        };
        let (names, spaces) = list(&[], 0);
        assert_eq!(names, ["a", "a.b", "a.b.c", "ab", "x.y"]);
        assert_eq!(spaces, ["a", "a.b", "x"]);
        assert_eq!(list(&[], 1).0, ["a", "ab"]);
        assert_eq!(list(&["a"], 0).0, ["a", "a.b", "a.b.c"]);
        assert_eq!(list(&["a"], 1).0, ["a"]);
        assert_eq!(list(&["a"], 2).0, ["a", "a.b"]);
    }
}
