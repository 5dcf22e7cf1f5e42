//! A recording's channels: per bus its joint states (CDR) and its frames,
//! events and setpoints (JSON, or JSON text in a `std_msgs/msg/String`),
//! their schemas, and the QoS a ROS 2 player republishes them with.

use std::collections::BTreeMap;
use std::io::Write;

use mcap::Writer;

use super::schemas;
use super::sink::Sink;
use crate::rosmsg::{JOINT_STATE_MSG, STRING_MSG};

/// What a bus's messages go to.
#[derive(Debug, Clone, Copy)]
pub struct BusChannels {
    pub joint_states: u16,
    pub frames: u16,
    pub events: u16,
    pub setpoints: u16,
}

/// Which channel of a bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Topic {
    JointStates,
    Frames,
    Events,
    Setpoints,
}

impl Topic {
    pub fn name(self, bus: &str) -> String {
        match self {
            Self::JointStates => format!("/{bus}/joint_states"),
            Self::Frames => format!("/jointd/{bus}/frames"),
            Self::Events => format!("/jointd/{bus}/events"),
            Self::Setpoints => format!("/jointd/{bus}/setpoints"),
        }
    }
}

/// The QoS a ROS 2 publisher of these topics offers, as rosbag2 writes a
/// channel's `offered_qos_profiles` (a YAML list of profiles, the policies
/// by name as rosbag2's metadata version 9 and later spell them): what the
/// ROS 2 bridge offers (reliable, volatile, keep last 10), durations
/// infinite as the middleware reports them, so `ros2 bag play` republishes
/// the topics with the QoS a live daemon offers.
pub const OFFERED_QOS_PROFILES: &str = "\
- history: keep_last
  depth: 10
  reliability: reliable
  durability: volatile
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false
";

/// How the frames, events and setpoints channels are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SideEncoding {
    /// JSON with a JSON schema (Foxglove shows the fields).
    #[default]
    Json,
    /// The same JSON text in a `std_msgs/msg/String`, CDR.
    RosString,
}

impl SideEncoding {
    /// The header's profile: `ros2` when every channel is CDR with a
    /// `ros2msg` schema (and its QoS), none otherwise.
    pub fn profile(self) -> &'static str {
        match self {
            Self::Json => "",
            Self::RosString => "ros2",
        }
    }
}

/// The schemas, and the four channels of each bus.
pub(super) fn add_channels<W: Write>(
    writer: &mut Writer<Sink<W>>,
    buses: &[String],
    side: SideEncoding,
) -> Result<BTreeMap<String, BusChannels>, mcap::McapError> {
    let joint_state = writer.add_schema(
        "sensor_msgs/msg/JointState",
        "ros2msg",
        JOINT_STATE_MSG.as_bytes(),
    )?;
    let mut json_schema = |name: &str, text: &str| match side {
        SideEncoding::Json => writer.add_schema(name, "jsonschema", text.as_bytes()),
        SideEncoding::RosString => {
            writer.add_schema("std_msgs/msg/String", "ros2msg", STRING_MSG.as_bytes())
        }
    };
    let frame = json_schema("jointd/Frame", &schemas::frame())?;
    let event = json_schema("jointd/BusEvent", &schemas::event())?;
    let setpoint = json_schema("jointd/Setpoints", &schemas::setpoint())?;
    let side_encoding = match side {
        SideEncoding::Json => "json",
        SideEncoding::RosString => "cdr",
    };
    let none = BTreeMap::new();
    let qos = BTreeMap::from([(
        "offered_qos_profiles".to_owned(),
        OFFERED_QOS_PROFILES.to_owned(),
    )]);
    let mut channels = BTreeMap::new();
    for bus in buses {
        let mut add = |schema, topic: Topic, encoding| {
            let metadata = if encoding == "cdr" { &qos } else { &none };
            writer.add_channel(schema, &topic.name(bus), encoding, metadata)
        };
        let ch = BusChannels {
            joint_states: add(joint_state, Topic::JointStates, "cdr")?,
            frames: add(frame, Topic::Frames, side_encoding)?,
            events: add(event, Topic::Events, side_encoding)?,
            setpoints: add(setpoint, Topic::Setpoints, side_encoding)?,
        };
        channels.insert(bus.clone(), ch);
    }
    Ok(channels)
}
