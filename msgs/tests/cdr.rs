//! CDR encoding: round trips of every type, exact byte layouts, and robustness against cut,
//! corrupted and foreign payloads.

mod common;

use common::{Rng, Sample};
use dynlab_msgs::ackermann_msgs::AckermannDriveStamped;
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::geometry_msgs::{Pose, PoseStamped, PoseWithCovariance, Quaternion};
use dynlab_msgs::nav_msgs::Path;
use dynlab_msgs::std_msgs::Header;
use dynlab_msgs::{CdrError, RosMessage, from_cdr, to_cdr};

const SAMPLES: usize = 40;

#[test]
fn every_type_round_trips_with_varied_values() {
    macro_rules! check {
        ($t:ty) => {{
            let mut rng = Rng::new(7);
            let mut distinct = std::collections::HashSet::new();
            for _ in 0..SAMPLES {
                let msg = <$t>::sample(&mut rng);
                let bytes = to_cdr(&msg).unwrap();
                let back: $t = from_cdr(&bytes).unwrap();
                assert_eq!(back, msg, "{}", <$t>::TYPE_NAME);
                // Bitwise: -0.0 == 0.0 under PartialEq, so compare the re-encoding too.
                assert_eq!(to_cdr(&back).unwrap(), bytes, "{}", <$t>::TYPE_NAME);
                distinct.insert(bytes);
            }
            assert!(
                distinct.len() > SAMPLES / 2,
                "{} samples are not varied",
                <$t>::TYPE_NAME
            );
        }};
    }
    for_every_type!(check);
}

#[test]
fn payload_cut_at_every_length_is_an_error() {
    macro_rules! check {
        ($t:ty) => {{
            let mut rng = Rng::new(11);
            for _ in 0..8 {
                let bytes = to_cdr(&<$t>::sample(&mut rng)).unwrap();
                for len in 0..bytes.len() {
                    assert!(
                        from_cdr::<$t>(&bytes[..len]).is_err(),
                        "{} cut to {len} of {} bytes decoded",
                        <$t>::TYPE_NAME,
                        bytes.len()
                    );
                }
            }
        }};
    }
    for_every_type!(check);
}

#[test]
fn corrupted_and_random_payloads_never_panic() {
    macro_rules! check {
        ($t:ty) => {{
            let mut rng = Rng::new(13);
            for _ in 0..4 {
                let bytes = to_cdr(&<$t>::sample(&mut rng)).unwrap();
                // Flip every byte of a valid payload, one at a time, to several values.
                for i in 0..bytes.len() {
                    for v in [0x00, 0xff, 0x80, rng.next_u64() as u8] {
                        let mut bad = bytes.clone();
                        bad[i] = v;
                        let _ = from_cdr::<$t>(&bad);
                    }
                }
            }
            for _ in 0..300 {
                let len = rng.below(200) as usize;
                let mut junk: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
                if junk.len() >= 2 {
                    junk[0] = 0;
                    junk[1] = rng.below(2) as u8;
                }
                let _ = from_cdr::<$t>(&junk);
            }
        }};
    }
    for_every_type!(check);
}

#[test]
fn huge_sequence_length_is_an_error_not_an_allocation() {
    let mut bytes = to_cdr(&Path::default()).unwrap();
    let n = bytes.len();
    bytes[n - 4..].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        from_cdr::<Path>(&bytes),
        Err(CdrError::Decode { .. })
    ));
}

#[test]
fn time_layout_is_int32_then_uint32_little_endian() {
    let bytes = to_cdr(&Time {
        sec: -2,
        nanosec: 0x0102_0304,
    })
    .unwrap();
    assert_eq!(bytes, [0, 1, 0, 0, 0xfe, 0xff, 0xff, 0xff, 4, 3, 2, 1]);
}

#[test]
fn header_string_has_length_with_terminator() {
    let bytes = to_cdr(&Header::new(Time { sec: 1, nanosec: 2 }, "ab")).unwrap();
    assert_eq!(
        bytes,
        [
            0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0
        ]
    );
}

#[test]
fn float64_after_string_is_aligned_to_8_from_body_start() {
    // Body: stamp 8 + length 4 + "a\0" 2 = 14, padded to 16, then 7 float64.
    let msg = PoseStamped {
        header: Header::new(Time::ZERO, "a"),
        pose: Pose::default(),
    };
    let bytes = to_cdr(&msg).unwrap();
    assert_eq!(bytes.len(), 4 + 16 + 56);
    assert_eq!(&bytes[4 + 14..4 + 16], &[0, 0]);
    assert_eq!(&bytes[bytes.len() - 8..], &1.0f64.to_le_bytes()); // orientation.w
}

#[test]
fn float32_fields_are_four_bytes_aligned_to_4() {
    // Body: stamp 8 + length 4 + "\0" 1 = 13, padded to 16, then 5 float32.
    let mut msg = AckermannDriveStamped::default();
    msg.drive.steering_angle = 0.25;
    msg.drive.jerk = -1.5;
    let bytes = to_cdr(&msg).unwrap();
    assert_eq!(bytes.len(), 4 + 16 + 20);
    assert_eq!(&bytes[20..24], &0.25f32.to_le_bytes());
    assert_eq!(&bytes[36..40], &(-1.5f32).to_le_bytes());
}

#[test]
fn fixed_size_covariance_has_no_length_prefix() {
    let mut msg = PoseWithCovariance::default();
    msg.covariance[0] = 2.0;
    msg.covariance[35] = 3.0;
    let bytes = to_cdr(&msg).unwrap();
    assert_eq!(bytes.len(), 4 + 7 * 8 + 36 * 8);
    assert_eq!(&bytes[4 + 56..4 + 64], &2.0f64.to_le_bytes());
    assert_eq!(&bytes[bytes.len() - 8..], &3.0f64.to_le_bytes());
}

#[test]
fn sequence_has_a_length_prefix() {
    let mut path = Path::default();
    let empty = to_cdr(&path).unwrap();
    // stamp 8 + length 4 + "\0" 1, padded to 16, then the element count.
    assert_eq!(empty.len(), 4 + 16 + 4);
    assert_eq!(&empty[20..24], &0u32.to_le_bytes());
    path.poses = vec![PoseStamped::default(); 3];
    let three = to_cdr(&path).unwrap();
    assert_eq!(&three[20..24], &3u32.to_le_bytes());
}

#[test]
fn big_endian_payloads_decode() {
    let msg = PoseStamped {
        header: Header::new(Time { sec: 5, nanosec: 6 }, "world"),
        pose: Pose {
            orientation: Quaternion::from_yaw(0.3),
            ..Pose::default()
        },
    };
    let mut bytes = vec![0, 0, 0, 0];
    cdr_encoding::to_writer::<_, byteorder::BigEndian, _>(&mut bytes, &msg).unwrap();
    assert_eq!(&bytes[4..8], &[0, 0, 0, 5]);
    assert_eq!(from_cdr::<PoseStamped>(&bytes).unwrap(), msg);
}

#[test]
fn trailing_padding_is_accepted_and_more_is_an_error() {
    let mut bytes = to_cdr(&Header::new(Time::ZERO, "a")).unwrap();
    bytes.extend([0, 0, 0]);
    assert!(from_cdr::<Header>(&bytes).is_ok());
    bytes.push(0);
    assert!(matches!(
        from_cdr::<Header>(&bytes),
        Err(CdrError::TrailingBytes { extra: 4, .. })
    ));
}

#[test]
fn foreign_encapsulations_are_named_in_the_error() {
    let mut bytes = to_cdr(&Time::ZERO).unwrap();
    bytes[1] = 0x07; // XCDR2 little endian
    let err = from_cdr::<Time>(&bytes).unwrap_err();
    assert!(matches!(err, CdrError::Encapsulation([0x00, 0x07])));
    assert!(err.to_string().contains("only plain CDR"), "{err}");
    assert!(matches!(
        from_cdr::<Time>(&[0, 1]),
        Err(CdrError::TooShort(2))
    ));
}

#[test]
fn invalid_utf8_in_a_string_is_an_error() {
    let mut bytes = to_cdr(&Header::new(Time::ZERO, "ab")).unwrap();
    bytes[16] = 0xff;
    assert!(matches!(
        from_cdr::<Header>(&bytes),
        Err(CdrError::Decode { .. })
    ));
}

#[test]
fn tf_message_layout_is_exact() {
    use dynlab_msgs::geometry_msgs::{Transform, TransformStamped};
    use dynlab_msgs::tf2_msgs::TFMessage;
    let msg = TFMessage {
        transforms: vec![TransformStamped {
            header: Header::new(Time { sec: 3, nanosec: 7 }, "world"),
            child_frame_id: "car".into(),
            transform: Transform::planar(1.5, -2.0, 0.0),
        }],
    };
    let bytes = to_cdr(&msg).unwrap();
    // header 4 | count 4 | stamp 8 | "world\0" 4 + 6 | pad 2 | "car\0" 4 + 4 | 7 × f64 at 32
    assert_eq!(bytes.len(), 4 + 32 + 56);
    assert_eq!(&bytes[4..8], &1u32.to_le_bytes());
    assert_eq!(&bytes[16..20], &6u32.to_le_bytes());
    assert_eq!(&bytes[20..26], b"world\0");
    assert_eq!(&bytes[28..32], &4u32.to_le_bytes());
    assert_eq!(&bytes[32..36], b"car\0");
    assert_eq!(&bytes[36..44], &1.5f64.to_le_bytes()); // translation.x
    assert_eq!(&bytes[bytes.len() - 8..], &1.0f64.to_le_bytes()); // rotation.w
    assert_eq!(from_cdr::<TFMessage>(&bytes).unwrap(), msg);
    // the definition: TFMessage, then TransformStamped's tree, each type once
    let def = TFMessage::definition();
    let names: Vec<&str> = def
        .lines()
        .filter_map(|l| l.strip_prefix("MSG: "))
        .collect();
    assert_eq!(
        names,
        [
            "geometry_msgs/TransformStamped",
            "geometry_msgs/Transform",
            "geometry_msgs/Quaternion",
            "geometry_msgs/Vector3",
            "std_msgs/Header",
            "builtin_interfaces/Time"
        ]
    );
}
