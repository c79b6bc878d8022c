//! Message definitions: composed as rosbag2 composes them, and well formed.

use dynlab_msgs::definition::{
    self, DefinitionError, SEPARATOR, blocks, check, compose, dependencies, known_msg_text,
};
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_msgs::nav_msgs::Odometry;
use dynlab_msgs::{RosMessage, all};

fn block_names(full: &str) -> Vec<String> {
    blocks(full)
        .unwrap()
        .iter()
        .skip(1)
        .map(|b| b.type_name.unwrap().to_string())
        .collect()
}

#[test]
fn every_definition_is_well_formed() {
    assert_eq!(all().len(), 22);
    for t in all() {
        check(t.definition, t.type_name).unwrap_or_else(|e| panic!("{}: {e}", t.type_name));
        let own = known_msg_text(t.type_name).unwrap();
        assert!(t.definition.starts_with(own), "{}", t.type_name);
        assert!(
            own.ends_with('\n'),
            "{} text must end with a newline",
            t.type_name
        );
        // Every block's text is the known text of the type it names.
        for b in blocks(t.definition).unwrap().iter().skip(1) {
            let name = b.type_name.unwrap();
            let expected = known_msg_text(name).unwrap();
            let last = b.text == expected;
            let inner = b.text.strip_suffix('\n') == Some(expected);
            assert!(last || inner, "{}: block {name} differs", t.type_name);
        }
    }
}

#[test]
fn pose_stamped_is_composed_exactly_as_rosbag2_does() {
    // rosbag2: own text, then for each dependency in sorted order (depth first, each once):
    // "\n", 80 '=', "\nMSG: pkg/Type\n", its text.
    let sep = |name: &str| format!("\n{SEPARATOR}\nMSG: {name}\n");
    let text = |name: &str| known_msg_text(name).unwrap();
    let expected = [
        text("geometry_msgs/PoseStamped").to_string(),
        sep("geometry_msgs/Pose"),
        text("geometry_msgs/Pose").into(),
        sep("geometry_msgs/Point"),
        text("geometry_msgs/Point").into(),
        sep("geometry_msgs/Quaternion"),
        text("geometry_msgs/Quaternion").into(),
        sep("std_msgs/Header"),
        text("std_msgs/Header").into(),
        sep("builtin_interfaces/Time"),
        text("builtin_interfaces/Time").into(),
    ]
    .concat();
    assert_eq!(PoseStamped::definition(), expected);
    assert_eq!(SEPARATOR.len(), 80);
    assert!(SEPARATOR.bytes().all(|b| b == b'='));
}

#[test]
fn odometry_dependencies_are_sorted_depth_first_and_written_once() {
    assert_eq!(
        block_names(Odometry::definition()),
        [
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
            "geometry_msgs/TwistWithCovariance",
            "geometry_msgs/Twist",
            "geometry_msgs/Vector3",
            "std_msgs/Header",
            "builtin_interfaces/Time",
        ]
    );
}

#[test]
fn leaf_types_have_no_blocks() {
    for name in [
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Vector3",
    ] {
        let t = dynlab_msgs::lookup(name).unwrap();
        assert_eq!(t.definition, known_msg_text(name).unwrap());
        assert!(!t.definition.contains(SEPARATOR));
    }
}

#[test]
fn dependency_rule_matches_rosbag2() {
    let text = "# comment Foo bar\n\
                std_msgs/Header header\n\
                  Pose  pose   # indented, extra spaces\n\
                float64[36] covariance\n\
                PoseStamped[] poses\n\
                Point[<=3] corners\n\
                uint8 CONSTANT=3\n\
                string<=10 bounded\n\
                \n\
                Pose again\n";
    let deps: Vec<String> = dependencies(text, "geometry_msgs").into_iter().collect();
    assert_eq!(
        deps,
        [
            "geometry_msgs/Point",
            "geometry_msgs/Pose",
            "geometry_msgs/PoseStamped",
            "std_msgs/Header"
        ]
    );
}

#[test]
fn compose_reports_a_missing_dependency() {
    let texts = |name: &str| match name {
        "a_msgs/msg/Root" => Some("b_msgs/Leaf leaf\n"),
        _ => None,
    };
    assert_eq!(
        compose("a_msgs/msg/Root", texts),
        Err(DefinitionError::NotFound {
            missing: "b_msgs/Leaf".into(),
            needed_by: "a_msgs/msg/Root".into()
        })
    );
    assert!(matches!(
        compose("not a type", |_| Some("")),
        Err(DefinitionError::InvalidTypeName(_))
    ));
}

#[test]
fn check_rejects_missing_duplicate_and_unused_blocks() {
    let block = |name: &str, text: &str| format!("{SEPARATOR}\nMSG: {name}\n{text}");
    let good = format!("Leaf leaf\n{}", block("a_msgs/Leaf", "int32 x\n"));
    assert_eq!(check(&good, "a_msgs/msg/Root"), Ok(()));
    assert_eq!(
        check("Leaf leaf\n", "a_msgs/msg/Root"),
        Err(DefinitionError::NotFound {
            missing: "a_msgs/Leaf".into(),
            needed_by: "a_msgs/Root".into()
        })
    );
    let twice = format!("{good}{}", block("a_msgs/Leaf", "int32 x\n"));
    assert_eq!(
        check(&twice, "a_msgs/msg/Root"),
        Err(DefinitionError::Duplicate("a_msgs/Leaf".into()))
    );
    let unused = format!("{good}{}", block("a_msgs/Other", "int32 y\n"));
    assert_eq!(
        check(&unused, "a_msgs/msg/Root"),
        Err(DefinitionError::Unused("a_msgs/Other".into()))
    );
    let no_msg_line = format!("Leaf leaf\n{SEPARATOR}\nint32 x\n");
    assert_eq!(
        check(&no_msg_line, "a_msgs/msg/Root"),
        Err(DefinitionError::MissingMsgLine { index: 1 })
    );
}

#[test]
fn blocks_reads_the_rosbags_layout_too() {
    // rosbags writes no blank line before a separator and may use `pkg/msg/Type` names.
    let full = format!("Leaf leaf\n{SEPARATOR}\nMSG: a_msgs/msg/Leaf\nint32 x\n");
    let b = blocks(&full).unwrap();
    assert_eq!(b.len(), 2);
    assert_eq!(b[0].text, "Leaf leaf\n");
    assert_eq!(b[1].type_name, Some("a_msgs/msg/Leaf"));
    assert_eq!(b[1].text, "int32 x\n");
    assert_eq!(check(&full, "a_msgs/msg/Root"), Ok(()));
    // A separator-like run of '=' inside a comment line is not a separator.
    let comment = format!("# {SEPARATOR}\nint32 x\n");
    assert_eq!(blocks(&comment).unwrap().len(), 1);
}

#[test]
fn type_names_split_into_package_and_type() {
    assert_eq!(
        definition::split_type_name("geometry_msgs/msg/Pose"),
        Some(("geometry_msgs", "Pose"))
    );
    assert_eq!(
        definition::split_type_name("geometry_msgs/Pose"),
        Some(("geometry_msgs", "Pose"))
    );
    assert_eq!(definition::split_type_name("Pose"), None);
    assert_eq!(definition::split_type_name("a//b"), None);
    assert_eq!(definition::split_type_name("1pkg/Type"), None);
    assert_eq!(definition::split_type_name("a/b/c/d"), None);
}

#[test]
fn push_action_definition_documents_meanings_and_ranges() {
    let def = dynlab_msgs::lookup("dynlab_msgs/msg/PushAction")
        .unwrap()
        .definition;
    for needle in [
        "float64 location",
        "float64 angle",
        "float64 length",
        "[-1, 1]",
        "[-pi/2, pi/2]",
        "[0, 1]",
        "0.1 m",
    ] {
        assert!(def.contains(needle), "missing {needle:?}");
    }
    assert!(def.is_ascii());
}

#[test]
fn two_level_schema_has_a_blank_line_before_the_separator() {
    // The layout rosbag2's own tests expect for a message with one nested message field.
    let texts = |name: &str| match name {
        "demo_msgs/Outer" => Some("demo_msgs/Inner b\n"),
        "demo_msgs/Inner" => Some("float32 c\n"),
        _ => None,
    };
    assert_eq!(
        compose("demo_msgs/Outer", texts).unwrap(),
        format!("demo_msgs/Inner b\n\n{SEPARATOR}\nMSG: demo_msgs/Inner\nfloat32 c\n")
    );
}
