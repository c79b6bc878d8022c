//! Simulator records as ROS 2 messages, and the bag layout of simulated data.
//!
//! One module for every producer of simulated data — `sim_node` and the `explorer` driver
//! publishing over DDS, and `dynlab collect` writing bags headless — so that a bag recorded over
//! DDS and a bag collected headless hold the same messages: same topics, types, frames, fields
//! and offered QoS. It depends on the simulator, the messages and the bag writer only, never on
//! DDS.
//!
//! | topic | type | frame | from |
//! |---|---|---|---|
//! | `/push/block_pose` | `geometry_msgs/msg/PoseStamped` | `table` | [`Pose2`] (measured) |
//! | `/push/action` | `dynlab_msgs/msg/PushAction` | `table` | [`PushAction`] |
//! | `/car/pose` | `geometry_msgs/msg/PoseStamped` | `world` | [`Pose2`] (measured) |
//! | `/car/cmd` | `ackermann_msgs/msg/AckermannDriveStamped` | `car` | [`CarInput`] |
//! | `/car/odom` | `nav_msgs/msg/Odometry` | `world` → `car` | [`CarState`] (ground truth, simulator only) |
//! | `/clock` | `rosgraph_msgs/msg/Clock` | — | simulation time |
//! | `/tf` | `tf2_msgs/msg/TFMessage` | `table` → `block`, `world` → `car` | [`Pose2`] (measured, as the pose topic) |
//! | `/tf_static` | `tf2_msgs/msg/TFMessage` | `world` → `table`; `car` → `car/front_axle`, `car/rear_axle` | fixed frames, once, latched |
//!
//! `/tf` carries the same measured pose as `/push/block_pose` or `/car/pose`, at the same stamps,
//! so a tool reading the frame pair `table:block` or `world:car` sees the same trajectory as one
//! reading the pose topic. `sim_node` always publishes both; `dynlab collect` writes them with
//! `--tf`.

use dynlab_bag::{BagError, BagSummary, BagWriter, QosDuration, TopicId, WriterOptions};
use dynlab_msgs::ackermann_msgs::{AckermannDrive, AckermannDriveStamped};
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::dynlab_msgs::PushAction as PushActionMsg;
use dynlab_msgs::geometry_msgs::{Pose, PoseStamped, Transform, TransformStamped, Twist, Vector3};
use dynlab_msgs::nav_msgs::Odometry;
use dynlab_msgs::rosgraph_msgs::Clock;
use dynlab_msgs::std_msgs::Header;
use dynlab_msgs::tf2_msgs::TFMessage;
use dynlab_sim::car::CarParams;
use dynlab_sim::{CarInput, CarState, Pose2, PushAction, Record, Sample};

/// Measured block pose.
pub const BLOCK_POSE_TOPIC: &str = "/push/block_pose";
/// Push actions.
pub const PUSH_ACTION_TOPIC: &str = "/push/action";
/// Measured car pose.
pub const CAR_POSE_TOPIC: &str = "/car/pose";
/// Car commands.
pub const CAR_CMD_TOPIC: &str = "/car/cmd";
/// Ground-truth car odometry (simulator only: a real car has no such topic).
pub const CAR_ODOM_TOPIC: &str = "/car/odom";
/// Simulation time.
pub const CLOCK_TOPIC: &str = "/clock";
/// Moving tf frames: the measured block or car pose.
pub const TF_TOPIC: &str = "/tf";
/// Fixed tf frames, published once and latched (transient local).
pub const TF_STATIC_TOPIC: &str = "/tf_static";

/// Frame of the pushing table (block poses and push actions).
pub const TABLE_FRAME: &str = "table";
/// Frame of the car's floor (car poses, odometry).
pub const WORLD_FRAME: &str = "world";
/// The car's body frame: odometry twists are expressed in it, commands are addressed to it.
pub const CAR_FRAME: &str = "car";
/// The block's body frame (tf child of `table`).
pub const BLOCK_FRAME: &str = "block";
/// The car's front axle centre (static tf child of `car`, `lf` ahead of the centre of mass).
pub const CAR_FRONT_AXLE_FRAME: &str = "car/front_axle";
/// The car's rear axle centre (static tf child of `car`, `lr` behind the centre of mass).
pub const CAR_REAR_AXLE_FRAME: &str = "car/rear_axle";

/// Which simulated robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SimWorld {
    /// The planar pusher (Tu & Lin).
    Push,
    /// The RC car (Kohler et al.).
    Car,
}

impl SimWorld {
    /// Parses `push` or `car`.
    pub fn parse(text: &str) -> Option<SimWorld> {
        match text {
            "push" => Some(SimWorld::Push),
            "car" => Some(SimWorld::Car),
            _ => None,
        }
    }

    /// `push` or `car`.
    pub fn name(self) -> &'static str {
        match self {
            SimWorld::Push => "push",
            SimWorld::Car => "car",
        }
    }

    /// The measured-pose topic.
    pub fn pose_topic(self) -> &'static str {
        match self {
            SimWorld::Push => BLOCK_POSE_TOPIC,
            SimWorld::Car => CAR_POSE_TOPIC,
        }
    }

    /// The command topic.
    pub fn command_topic(self) -> &'static str {
        match self {
            SimWorld::Push => PUSH_ACTION_TOPIC,
            SimWorld::Car => CAR_CMD_TOPIC,
        }
    }

    /// The tf frame pair `(parent, child)` of the measured pose: `table → block` or
    /// `world → car`.
    pub fn tf_frames(self) -> (&'static str, &'static str) {
        match self {
            SimWorld::Push => (TABLE_FRAME, BLOCK_FRAME),
            SimWorld::Car => (WORLD_FRAME, CAR_FRAME),
        }
    }
}

/// The QoS class a topic is offered with by the simulator and the exploration driver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OfferedQos {
    /// `sensor_data`: best effort, keep last 5 (poses, odometry).
    SensorData,
    /// `default`: reliable, keep last 10 (commands and actions: none may be lost).
    Reliable,
    /// `clock`: best effort, keep last 1.
    Clock,
    /// `/tf` as tf2's broadcaster offers it: reliable, keep last 100, volatile.
    Tf,
    /// `/tf_static` as tf2's static broadcaster offers it: reliable, keep last 1, transient
    /// local (latched).
    TfStatic,
}

impl OfferedQos {
    /// The profile rosbag2 — and our `recorder` — stores for a remote publisher offering this
    /// class: history is not in DDS discovery data, so it is `unknown` with depth 0; deadline,
    /// lifespan and lease are infinite.
    pub fn recorded_profile(self) -> dynlab_bag::QosProfile {
        dynlab_bag::QosProfile {
            history: dynlab_bag::History::Unknown,
            depth: 0,
            reliability: match self {
                OfferedQos::Reliable | OfferedQos::Tf | OfferedQos::TfStatic => {
                    dynlab_bag::Reliability::Reliable
                }
                OfferedQos::SensorData | OfferedQos::Clock => dynlab_bag::Reliability::BestEffort,
            },
            durability: match self {
                OfferedQos::TfStatic => dynlab_bag::Durability::TransientLocal,
                _ => dynlab_bag::Durability::Volatile,
            },
            deadline: QosDuration::INFINITE,
            lifespan: QosDuration::INFINITE,
            liveliness: dynlab_bag::Liveliness::Automatic,
            liveliness_lease_duration: QosDuration::INFINITE,
            avoid_ros_namespace_conventions: false,
        }
    }
}

/// A topic of simulated data: name, ROS type and the QoS its publisher offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimTopic {
    /// Topic name.
    pub name: &'static str,
    /// ROS type name.
    pub type_name: &'static str,
    /// Offered QoS.
    pub qos: OfferedQos,
}

/// The topics of a world, in the order they are added to a bag; `/clock` last when asked for.
pub fn sim_topics(world: SimWorld, clock: bool) -> Vec<SimTopic> {
    use dynlab_msgs::RosMessage;
    let mut t = match world {
        SimWorld::Push => vec![
            SimTopic {
                name: BLOCK_POSE_TOPIC,
                type_name: PoseStamped::TYPE_NAME,
                qos: OfferedQos::SensorData,
            },
            SimTopic {
                name: PUSH_ACTION_TOPIC,
                type_name: PushActionMsg::TYPE_NAME,
                qos: OfferedQos::Reliable,
            },
        ],
        SimWorld::Car => vec![
            SimTopic {
                name: CAR_POSE_TOPIC,
                type_name: PoseStamped::TYPE_NAME,
                qos: OfferedQos::SensorData,
            },
            SimTopic {
                name: CAR_CMD_TOPIC,
                type_name: AckermannDriveStamped::TYPE_NAME,
                qos: OfferedQos::Reliable,
            },
            SimTopic {
                name: CAR_ODOM_TOPIC,
                type_name: Odometry::TYPE_NAME,
                qos: OfferedQos::SensorData,
            },
        ],
    };
    if clock {
        t.push(SimTopic {
            name: CLOCK_TOPIC,
            type_name: Clock::TYPE_NAME,
            qos: OfferedQos::Clock,
        });
    }
    t
}

/// `/tf` and `/tf_static`, in the order they are added to a bag.
pub fn tf_topics() -> [SimTopic; 2] {
    use dynlab_msgs::RosMessage;
    [
        SimTopic {
            name: TF_TOPIC,
            type_name: TFMessage::TYPE_NAME,
            qos: OfferedQos::Tf,
        },
        SimTopic {
            name: TF_STATIC_TOPIC,
            type_name: TFMessage::TYPE_NAME,
            qos: OfferedQos::TfStatic,
        },
    ]
}

/// Simulation time `t_ns` as a ROS time (saturating after 68 years of simulated time).
pub fn stamp(t_ns: u64) -> Time {
    Time::from_nanos(i64::try_from(t_ns).unwrap_or(i64::MAX))
}

fn header(t_ns: u64, frame: &str) -> Header {
    Header::new(stamp(t_ns), frame)
}

/// A planar pose as `PoseStamped` in `frame` (z = 0, yaw as a unit quaternion about z).
pub fn pose_msg(t_ns: u64, frame: &str, pose: Pose2) -> PoseStamped {
    PoseStamped {
        header: header(t_ns, frame),
        pose: Pose::planar(pose.x, pose.y, pose.theta),
    }
}

/// A measured block pose on `/push/block_pose`.
pub fn block_pose_msg(t_ns: u64, pose: Pose2) -> PoseStamped {
    pose_msg(t_ns, TABLE_FRAME, pose)
}

/// A measured car pose on `/car/pose`.
pub fn car_pose_msg(t_ns: u64, pose: Pose2) -> PoseStamped {
    pose_msg(t_ns, WORLD_FRAME, pose)
}

/// A push on `/push/action`.
pub fn push_action_msg(t_ns: u64, action: PushAction) -> PushActionMsg {
    PushActionMsg {
        header: header(t_ns, TABLE_FRAME),
        location: action.location,
        angle: action.angle,
        length: action.length,
    }
}

/// A car command on `/car/cmd`: `steering_angle` = δ, `acceleration` = throttle; the other
/// fields are zero. The message carries `float32`, so the command is rounded to the nearest
/// `f32` (the simulator applies what a subscriber would read: see [`car_input_from_msg`]).
pub fn car_cmd_msg(t_ns: u64, u: CarInput) -> AckermannDriveStamped {
    AckermannDriveStamped {
        header: header(t_ns, CAR_FRAME),
        drive: AckermannDrive {
            steering_angle: u.steering as f32,
            acceleration: u.throttle as f32,
            ..AckermannDrive::default()
        },
    }
}

/// Ground-truth odometry on `/car/odom` (simulator only): pose in `world`, body-frame twist
/// `(vx, vy, ω)` in `car`, covariances zero (exact).
pub fn car_odom_msg(t_ns: u64, s: &CarState) -> Odometry {
    let mut odom = Odometry {
        header: header(t_ns, WORLD_FRAME),
        child_frame_id: CAR_FRAME.to_string(),
        ..Odometry::default()
    };
    odom.pose.pose = Pose::planar(s.x, s.y, s.psi);
    odom.twist.twist = Twist {
        linear: Vector3 {
            x: s.vx,
            y: s.vy,
            z: 0.0,
        },
        angular: Vector3 {
            x: 0.0,
            y: 0.0,
            z: s.omega,
        },
    };
    odom
}

fn transform(t_ns: u64, parent: &str, child: &str, x: f64, y: f64, yaw: f64) -> TransformStamped {
    TransformStamped {
        header: header(t_ns, parent),
        child_frame_id: child.to_string(),
        transform: Transform::planar(x, y, yaw),
    }
}

/// `/tf` with the measured pose: `table → block` (pushing) or `world → car`, the same values
/// and stamp as the pose topic's message.
pub fn tf_msg(world: SimWorld, t_ns: u64, pose: Pose2) -> TFMessage {
    let (parent, child) = world.tf_frames();
    TFMessage {
        transforms: vec![transform(t_ns, parent, child, pose.x, pose.y, pose.theta)],
    }
}

/// `/tf_static`, published once: pushing `world → table` (the identity: the table frame is the
/// world frame); the car `car → car/front_axle` and `car → car/rear_axle` (`lf` ahead of and
/// `lr` behind the centre of mass, from `car`).
pub fn tf_static_msg(world: SimWorld, t_ns: u64, car: &CarParams) -> TFMessage {
    let transforms = match world {
        SimWorld::Push => vec![transform(t_ns, WORLD_FRAME, TABLE_FRAME, 0.0, 0.0, 0.0)],
        SimWorld::Car => vec![
            transform(t_ns, CAR_FRAME, CAR_FRONT_AXLE_FRAME, car.lf, 0.0, 0.0),
            transform(t_ns, CAR_FRAME, CAR_REAR_AXLE_FRAME, -car.lr, 0.0, 0.0),
        ],
    };
    TFMessage { transforms }
}

/// `/clock` at simulation time `t_ns`.
pub fn clock_msg(t_ns: u64) -> Clock {
    Clock { clock: stamp(t_ns) }
}

/// A field of an incoming command that was changed or refused, for a warning that names it.
#[derive(Debug, Clone, PartialEq)]
pub struct InputIssue {
    /// Message field, e.g. `location` or `drive.steering_angle`.
    pub field: &'static str,
    /// The value received.
    pub value: f64,
    /// What was done and the accepted range.
    pub note: String,
}

impl std::fmt::Display for InputIssue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} = {}: {}", self.field, self.value, self.note)
    }
}

/// An incoming command that cannot be used at all (a NaN or infinite field).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("rejected: {}", .issues.iter().map(|i| i.to_string()).collect::<Vec<_>>().join("; "))]
pub struct RejectedInput {
    /// Every non-finite field.
    pub issues: Vec<InputIssue>,
}

fn check_range(
    field: &'static str,
    value: f64,
    (lo, hi): (f64, f64),
    issues: &mut Vec<InputIssue>,
) -> f64 {
    if value < lo || value > hi {
        issues.push(InputIssue {
            field,
            value,
            note: format!("outside [{lo}, {hi}], clamped"),
        });
    }
    value.clamp(lo, hi)
}

fn non_finite(fields: &[(&'static str, f64)]) -> Result<(), RejectedInput> {
    let issues: Vec<InputIssue> = fields
        .iter()
        .filter(|(_, v)| !v.is_finite())
        .map(|&(field, value)| InputIssue {
            field,
            value,
            note: "not a finite number; the whole command is ignored".to_string(),
        })
        .collect();
    if issues.is_empty() {
        Ok(())
    } else {
        Err(RejectedInput { issues })
    }
}

/// The push a `/push/action` message asks for. A NaN or infinite field rejects the message;
/// a field outside its range (`location` ∈ [−1, 1], `angle` ∈ [−π/2, π/2], `length` ∈ [0, 1])
/// is clamped into it, as Tu & Lin's environment clips actions, and reported.
pub fn push_action_from_msg(
    msg: &PushActionMsg,
) -> Result<(PushAction, Vec<InputIssue>), RejectedInput> {
    non_finite(&[
        ("location", msg.location),
        ("angle", msg.angle),
        ("length", msg.length),
    ])?;
    let mut issues = Vec::new();
    let location = check_range(
        "location",
        msg.location,
        PushActionMsg::LOCATION_RANGE,
        &mut issues,
    );
    let angle = check_range("angle", msg.angle, PushActionMsg::ANGLE_RANGE, &mut issues);
    let length = check_range(
        "length",
        msg.length,
        PushActionMsg::LENGTH_RANGE,
        &mut issues,
    );
    Ok((PushAction::new(location, angle, length), issues))
}

/// The command a `/car/cmd` message asks for, with the car's limits. A NaN or infinite
/// `steering_angle` or `acceleration` rejects the message; a value beyond the limits
/// (`±steering_max`, `[throttle_min, throttle_max]`) is clamped and reported.
pub fn car_input_from_msg(
    msg: &AckermannDriveStamped,
    car: &CarParams,
) -> Result<(CarInput, Vec<InputIssue>), RejectedInput> {
    let steering = f64::from(msg.drive.steering_angle);
    let throttle = f64::from(msg.drive.acceleration);
    non_finite(&[
        ("drive.steering_angle", steering),
        ("drive.acceleration", throttle),
    ])?;
    let mut issues = Vec::new();
    let steering = check_range(
        "drive.steering_angle",
        steering,
        (-car.steering_max, car.steering_max),
        &mut issues,
    );
    let throttle = check_range(
        "drive.acceleration",
        throttle,
        (car.throttle_min, car.throttle_max),
        &mut issues,
    );
    Ok((CarInput::new(steering, throttle), issues))
}

/// Writes simulated records into a bag exactly as `recorder` stores the same topics published
/// by `sim_node` and `explorer`: same topics, types, definitions and offered QoS. Log time and
/// header stamp are both the simulation time of the record.
pub struct SimBagWriter {
    writer: BagWriter,
    world: SimWorld,
    pose: TopicId,
    command: TopicId,
    odom: Option<TopicId>,
    clock: Option<TopicId>,
    tf: Option<TfTopics>,
}

/// `/tf` and `/tf_static` of a [`SimBagWriter`], and the static transforms still to write.
struct TfTopics {
    tf: TopicId,
    tf_static: TopicId,
    pending_static: Option<CarParams>,
}

/// Problems writing simulated data.
#[derive(Debug, thiserror::Error)]
pub enum SimBagError {
    /// The bag writer failed.
    #[error(transparent)]
    Bag(#[from] BagError),
    /// A record of the other world was given (a car record to a pushing bag).
    #[error("a {record} record cannot go into a {world} bag (collect car data into a car bag)")]
    WrongWorld {
        /// The record kind.
        record: &'static str,
        /// The bag's world.
        world: &'static str,
    },
}

impl SimBagWriter {
    /// Creates the bag directory `dir` with the topics of `world` (and `/clock` at every pose
    /// stamp when `clock` is set).
    pub fn create(
        dir: &std::path::Path,
        world: SimWorld,
        clock: bool,
        options: WriterOptions,
    ) -> Result<SimBagWriter, SimBagError> {
        let mut writer = BagWriter::create(dir, options)?;
        let mut ids = Vec::new();
        for t in sim_topics(world, clock) {
            let def = dynlab_msgs::lookup(t.type_name)
                .map(|m| m.definition)
                .unwrap_or_default();
            ids.push(writer.add_topic(t.name, t.type_name, def, &[t.qos.recorded_profile()])?);
        }
        let (pose, command) = (ids[0], ids[1]);
        let (odom, clock) = match world {
            SimWorld::Push => (None, clock.then(|| ids[2])),
            SimWorld::Car => (Some(ids[2]), clock.then(|| ids[3])),
        };
        Ok(SimBagWriter {
            writer,
            world,
            pose,
            command,
            odom,
            clock,
            tf: None,
        })
    }

    /// Also writes `/tf` (the measured pose, at every pose) and `/tf_static` (once, at the first
    /// pose), as `sim_node` publishes them; `car` gives the axle positions of the car's static
    /// frames (ignored for pushing).
    pub fn with_tf(mut self, car: &CarParams) -> Result<SimBagWriter, SimBagError> {
        let [tf, tf_static] = tf_topics().map(|t| {
            self.writer.add_topic(
                t.name,
                t.type_name,
                <TFMessage as dynlab_msgs::RosMessage>::definition(),
                &[t.qos.recorded_profile()],
            )
        });
        self.tf = Some(TfTopics {
            tf: tf?,
            tf_static: tf_static?,
            pending_static: Some(car.clone()),
        });
        Ok(self)
    }

    fn write_tf(&mut self, t: u64, pose: Pose2) -> Result<(), SimBagError> {
        let world = self.world;
        if let Some(tf) = &mut self.tf {
            if let Some(car) = tf.pending_static.take() {
                self.writer
                    .write(tf.tf_static, t, &tf_static_msg(world, t, &car))?;
            }
            self.writer.write(tf.tf, t, &tf_msg(world, t, pose))?;
        }
        Ok(())
    }

    /// Writes one record at its simulation time (a pose also writes `/clock` when enabled).
    pub fn write(&mut self, sample: &Sample) -> Result<(), SimBagError> {
        let t = sample.t_ns;
        let wrong = |record| SimBagError::WrongWorld {
            record,
            world: self.world.name(),
        };
        match (self.world, sample.record) {
            (SimWorld::Push, Record::BlockPose(p)) => {
                self.write_clock(t)?;
                self.writer.write(self.pose, t, &block_pose_msg(t, p))?;
                self.write_tf(t, p)?;
            }
            (SimWorld::Push, Record::PushAction(a)) => {
                self.writer.write(self.command, t, &push_action_msg(t, a))?;
            }
            (SimWorld::Car, Record::CarPose(p)) => {
                self.write_clock(t)?;
                self.writer.write(self.pose, t, &car_pose_msg(t, p))?;
                self.write_tf(t, p)?;
            }
            (SimWorld::Car, Record::CarCmd(u)) => {
                self.writer.write(self.command, t, &car_cmd_msg(t, u))?;
            }
            (SimWorld::Car, Record::CarOdom(s)) => {
                let id = self.odom.ok_or_else(|| wrong("CarOdom"))?;
                self.writer.write(id, t, &car_odom_msg(t, &s))?;
            }
            (_, Record::BlockPose(_)) => return Err(wrong("BlockPose")),
            (_, Record::PushAction(_)) => return Err(wrong("PushAction")),
            (_, Record::CarPose(_)) => return Err(wrong("CarPose")),
            (_, Record::CarCmd(_)) => return Err(wrong("CarCmd")),
            (_, Record::CarOdom(_)) => return Err(wrong("CarOdom")),
        }
        Ok(())
    }

    fn write_clock(&mut self, t: u64) -> Result<(), SimBagError> {
        if let Some(id) = self.clock {
            self.writer.write(id, t, &clock_msg(t))?;
        }
        Ok(())
    }

    /// Finishes the bag.
    pub fn finish(self) -> Result<BagSummary, SimBagError> {
        Ok(self.writer.finish()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_actions_are_clamped_or_rejected_naming_the_field() {
        let mut m = push_action_msg(0, PushAction::new(0.5, 0.1, 0.3));
        let (a, issues) = push_action_from_msg(&m).unwrap();
        assert!(issues.is_empty());
        assert_eq!((a.location, a.angle, a.length), (0.5, 0.1, 0.3));
        m.location = 1.5;
        m.length = -0.2;
        let (a, issues) = push_action_from_msg(&m).unwrap();
        assert_eq!((a.location, a.length), (1.0, 0.0));
        let fields: Vec<_> = issues.iter().map(|i| i.field).collect();
        assert_eq!(fields, ["location", "length"]);
        assert!(
            issues[0]
                .to_string()
                .contains("location = 1.5: outside [-1, 1], clamped")
        );
        m.angle = f64::NAN;
        let err = push_action_from_msg(&m).unwrap_err();
        assert_eq!(err.issues.len(), 1);
        assert!(err.to_string().contains("angle = NaN"), "{err}");
    }

    #[test]
    fn car_commands_are_clamped_to_the_car_limits_or_rejected() {
        let car = CarParams::default();
        let (u, issues) =
            car_input_from_msg(&car_cmd_msg(0, CarInput::new(0.5, -0.5)), &car).unwrap();
        assert_eq!(u.steering, car.steering_max);
        assert_eq!(u.throttle, car.throttle_min);
        assert_eq!(issues.len(), 2);
        assert_eq!(issues[0].field, "drive.steering_angle");
        let mut m = car_cmd_msg(0, CarInput::new(0.1, 0.2));
        m.drive.acceleration = f32::INFINITY;
        let err = car_input_from_msg(&m, &car).unwrap_err();
        assert_eq!(err.issues[0].field, "drive.acceleration");
        // the f32 command is what the simulator applies
        let (u, _) = car_input_from_msg(&car_cmd_msg(0, CarInput::new(0.1, 0.2)), &car).unwrap();
        assert_eq!(u.steering, f64::from(0.1f32));
    }

    #[test]
    fn tf_carries_the_measured_pose_of_the_pose_topic_and_static_frames() {
        let p = Pose2::new(0.4, -0.1, 2.5);
        for world in [SimWorld::Push, SimWorld::Car] {
            let t = 1_250_000_000;
            let msg = tf_msg(world, t, p);
            let pose = pose_msg(t, world.tf_frames().0, p);
            assert_eq!(msg.transforms.len(), 1);
            let tr = &msg.transforms[0];
            assert_eq!(tr.header, pose.header);
            assert_eq!(tr.child_frame_id, world.tf_frames().1);
            assert_eq!(tr.transform.as_pose(), pose.pose);
        }
        assert_eq!(SimWorld::Car.tf_frames(), ("world", "car"));
        assert_eq!(SimWorld::Push.tf_frames(), ("table", "block"));
        let car = CarParams::default();
        let s = tf_static_msg(SimWorld::Car, 0, &car);
        let axles: Vec<(&str, &str, f64)> = s
            .transforms
            .iter()
            .map(|t| {
                (
                    t.header.frame_id.as_str(),
                    t.child_frame_id.as_str(),
                    t.transform.translation.x,
                )
            })
            .collect();
        assert_eq!(
            axles,
            [
                ("car", "car/front_axle", car.lf),
                ("car", "car/rear_axle", -car.lr)
            ]
        );
        let s = tf_static_msg(SimWorld::Push, 0, &car);
        assert_eq!(s.transforms[0].header.frame_id, "world");
        assert_eq!(s.transforms[0].child_frame_id, "table");
        // /tf_static is latched in the bag's QoS as well
        let [tf, tf_static] = tf_topics();
        assert_eq!(
            tf_static.qos.recorded_profile().durability,
            dynlab_bag::Durability::TransientLocal
        );
        assert_eq!(
            tf.qos.recorded_profile().reliability,
            dynlab_bag::Reliability::Reliable
        );
    }

    #[test]
    fn odometry_carries_the_body_twist_in_the_car_frame() {
        let s = CarState {
            x: 1.0,
            y: -2.0,
            psi: 0.5,
            vx: 1.5,
            vy: -0.25,
            omega: 3.0,
        };
        let o = car_odom_msg(1_500_000_000, &s);
        assert_eq!(o.header.frame_id, WORLD_FRAME);
        assert_eq!(o.child_frame_id, CAR_FRAME);
        assert_eq!(o.header.stamp.sec, 1);
        assert_eq!(o.header.stamp.nanosec, 500_000_000);
        assert_eq!(o.twist.twist.linear.x, 1.5);
        assert_eq!(o.twist.twist.linear.y, -0.25);
        assert_eq!(o.twist.twist.angular.z, 3.0);
        assert!((o.pose.pose.orientation.yaw() - 0.5).abs() < 1e-12);
    }
}
