//! A recording's channels: per bus its joint states (CDR) and its frames,
//! events and setpoints (JSON, or JSON text in a `std_msgs/msg/String`),
//! their schemas, and the QoS a ROS 2 player republishes them with.
//!
//! One table ([`specs`]) says what each channel is: a recording declares
//! its channels from it and the live Foxglove view advertises the same, so
//! one Foxglove layout works on a file and live.

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
    /// Every channel of a bus, in the order a recording declares them.
    pub const ALL: [Topic; 4] = [
        Topic::JointStates,
        Topic::Frames,
        Topic::Events,
        Topic::Setpoints,
    ];

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

/// One channel of a bus: its topic, its messages' encoding, its schema
/// and its metadata, as a recording declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelSpec {
    pub topic: Topic,
    /// The topic's name, e.g. `/sim0/joint_states`.
    pub name: String,
    /// The messages' encoding: `cdr` or `json`.
    pub encoding: &'static str,
    pub schema_name: &'static str,
    /// `ros2msg` or `jsonschema`.
    pub schema_encoding: &'static str,
    /// The schema's text (a message definition or a JSON schema).
    pub schema: String,
    /// `offered_qos_profiles` on a CDR channel, nothing on a JSON one.
    pub metadata: BTreeMap<String, String>,
}

/// The four channels of `bus`, in [`Topic::ALL`]'s order.
pub fn specs(bus: &str, side: SideEncoding) -> Vec<ChannelSpec> {
    Topic::ALL.iter().map(|&t| spec(bus, t, side)).collect()
}

fn spec(bus: &str, topic: Topic, side: SideEncoding) -> ChannelSpec {
    let (schema_name, schema) = match topic {
        Topic::JointStates => {
            return cdr(bus, topic, "sensor_msgs/msg/JointState", JOINT_STATE_MSG)
        }
        Topic::Frames => ("jointd/Frame", schemas::frame()),
        Topic::Events => ("jointd/BusEvent", schemas::event()),
        Topic::Setpoints => ("jointd/Setpoints", schemas::setpoint()),
    };
    match side {
        SideEncoding::Json => ChannelSpec {
            topic,
            name: topic.name(bus),
            encoding: "json",
            schema_name,
            schema_encoding: "jsonschema",
            schema,
            metadata: BTreeMap::new(),
        },
        SideEncoding::RosString => cdr(bus, topic, "std_msgs/msg/String", STRING_MSG),
    }
}

/// A CDR channel with a `ros2msg` schema and the QoS it is offered with.
fn cdr(bus: &str, topic: Topic, schema_name: &'static str, definition: &str) -> ChannelSpec {
    ChannelSpec {
        topic,
        name: topic.name(bus),
        encoding: "cdr",
        schema_name,
        schema_encoding: "ros2msg",
        schema: definition.to_owned(),
        metadata: BTreeMap::from([(
            "offered_qos_profiles".to_owned(),
            OFFERED_QOS_PROFILES.to_owned(),
        )]),
    }
}

/// The schemas, and the four channels of each bus (the writer writes a
/// schema once, however many channels name it).
pub(super) fn add_channels<W: Write>(
    writer: &mut Writer<Sink<W>>,
    buses: &[String],
    side: SideEncoding,
) -> Result<BTreeMap<String, BusChannels>, mcap::McapError> {
    let mut channels = BTreeMap::new();
    for bus in buses {
        let mut ch = BusChannels {
            joint_states: 0,
            frames: 0,
            events: 0,
            setpoints: 0,
        };
        for s in specs(bus, side) {
            let schema =
                writer.add_schema(s.schema_name, s.schema_encoding, s.schema.as_bytes())?;
            let id = writer.add_channel(schema, &s.name, s.encoding, &s.metadata)?;
            match s.topic {
                Topic::JointStates => ch.joint_states = id,
                Topic::Frames => ch.frames = id,
                Topic::Events => ch.events = id,
                Topic::Setpoints => ch.setpoints = id,
            }
        }
        channels.insert(bus.clone(), ch);
    }
    Ok(channels)
}
