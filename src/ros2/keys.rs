//! Names on the Zenoh network as rmw_zenoh gives them, so that ROS 2 nodes
//! running `rmw_zenoh_cpp` see jointd's topics and it sees theirs. From
//! rmw_zenoh's design document (`docs/design.md` of ros2/rmw_zenoh,
//! "Topic and Service name mapping to Zenoh key expressions", "Graph
//! Cache", "Publishers"):
//!
//! - data: `<domain_id>/<fully qualified topic, no leading />/<DDS type
//!   name>/<type hash>`;
//! - liveliness tokens: `@ros2_lv/<domain_id>/<session id>/<node id>/<entity
//!   id>/<kind>/<enclave>/<namespace>/<node name>[/<topic>/<type>/<hash>/<qos>]`,
//!   with `/` in names replaced by `%` and an empty name written `%`;
//! - the attachment of every sample: sequence number (i64 LE), source
//!   timestamp (ns since the epoch, i64 LE), the GID's length (one byte,
//!   16) and the publisher's 16-byte GID.
//!
//! Type hashes (REP-2016, RIHS01), as `ros2 topic info --verbose` prints
//! them on Jazzy and as `rosbags` computes them from the definitions:
//! `sensor_msgs/msg/JointState` [`JOINT_STATE_HASH`],
//! `diagnostic_msgs/msg/DiagnosticArray` [`DIAGNOSTIC_ARRAY_HASH`],
//! `trajectory_msgs/msg/JointTrajectory` [`JOINT_TRAJECTORY_HASH`],
//! `rcl_interfaces/msg/Log` [`LOG_HASH`],
//! `control_msgs/msg/GripperCommand` [`GRIPPER_COMMAND_HASH`] (`float64
//! position`, `float64 max_effort`: computed as `rosbags` computes the
//! others, from the definition; no published value was found to compare
//! with, so the Python test derives it from the definition and checks the
//! same method against the published `JointState` and `AddTwoInts` hashes).
//!
//! Services (rmw_zenoh's `rmw_service_data.cpp`): a queryable on
//! `<domain_id>/<service, no leading />/<DDS service type>/<hash>`, the
//! type being the service's (`std_srvs::srv::dds_::SetBool_`, not its
//! `Request_` or `Response_`), its hash the service's type description's
//! (request, response and event message; REP-2016); a request's
//! attachment is the client's sequence number, timestamp and GID, and the
//! reply's carries the same sequence number and GID with the server's
//! timestamp. Service hashes are computed as `rosbags` computes message
//! hashes, over the service description; the method gives the design
//! document's `example_interfaces/srv/AddTwoInts` hash
//! (`RIHS01_e118de6b…`) to the bit.

use super::config::Distro;

pub const JOINT_STATE_TYPE: &str = "sensor_msgs::msg::dds_::JointState_";
pub const JOINT_STATE_HASH: &str =
    "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e";
pub const DIAGNOSTIC_ARRAY_TYPE: &str = "diagnostic_msgs::msg::dds_::DiagnosticArray_";
pub const DIAGNOSTIC_ARRAY_HASH: &str =
    "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e";

pub const JOINT_TRAJECTORY_TYPE: &str = "trajectory_msgs::msg::dds_::JointTrajectory_";
pub const JOINT_TRAJECTORY_HASH: &str =
    "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e";
pub const LOG_TYPE: &str = "rcl_interfaces::msg::dds_::Log_";
pub const LOG_HASH: &str =
    "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac";
pub const GRIPPER_COMMAND_TYPE: &str = "control_msgs::msg::dds_::GripperCommand_";
pub const GRIPPER_COMMAND_HASH: &str =
    "RIHS01_57eb8f326c9889ca8bb34ead82cc94cc09bf6bc5c3b6c09546dca3a00b589890";
pub const SET_BOOL_TYPE: &str = "std_srvs::srv::dds_::SetBool_";
pub const SET_BOOL_HASH: &str =
    "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a";
pub const TRIGGER_TYPE: &str = "std_srvs::srv::dds_::Trigger_";
pub const TRIGGER_HASH: &str =
    "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f";

/// What rmw_zenoh on Humble writes where Jazzy writes a type hash
/// (Humble's type support has none).
pub const HUMBLE_HASH: &str = "TypeHashNotSupported";

/// The hash to write in keys and tokens for `distro`.
pub fn type_hash(distro: Distro, jazzy: &'static str) -> &'static str {
    match distro {
        Distro::Jazzy => jazzy,
        Distro::Humble => HUMBLE_HASH,
    }
}

/// The QoS every jointd endpoint declares, in rmw_zenoh's compact form:
/// reliability, durability and history kinds left at their defaults
/// (reliable, volatile, keep last), depth 10, no deadline, lifespan or
/// liveliness lease.
pub const QOS: &str = "::,10:,:,:,,";

/// What an endpoint is, in a liveliness token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Publisher,
    Subscription,
    /// A service server.
    Service,
}

impl Kind {
    fn code(self) -> &'static str {
        match self {
            Self::Publisher => "MP",
            Self::Subscription => "MS",
            Self::Service => "SS",
        }
    }
}

/// `/` → `%`; an empty name is `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// A topic's fully qualified name: `/<namespace>/<topic>`.
pub fn qualified(namespace: &str, topic: &str) -> String {
    let ns = namespace.trim_matches('/');
    if ns.is_empty() {
        format!("/{topic}")
    } else {
        format!("/{ns}/{topic}")
    }
}

/// The key expression a topic's samples travel on.
pub fn topic_key(domain: u32, qualified: &str, type_name: &str, hash: &str) -> String {
    format!(
        "{domain}/{}/{type_name}/{hash}",
        qualified.trim_start_matches('/')
    )
}

/// Who declares tokens: one session, one node.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeIdentity {
    pub domain: u32,
    /// The Zenoh session id, as Zenoh prints it.
    pub session: String,
    pub node_id: u32,
    /// The node's namespace (`/` or empty: none).
    pub namespace: String,
    pub name: String,
}

impl NodeIdentity {
    fn prefix(&self, entity_id: u32, kind: &str) -> String {
        let ns = self.namespace.trim_matches('/');
        let ns = if ns.is_empty() {
            "%".to_owned()
        } else {
            mangle(&format!("/{ns}"))
        };
        format!(
            "@ros2_lv/{}/{}/{}/{entity_id}/{kind}/%/{ns}/{}",
            self.domain, self.session, self.node_id, self.name
        )
    }

    /// The node's own token (its entity id is its node id).
    pub fn node_token(&self) -> String {
        self.prefix(self.node_id, "NN")
    }

    /// A publisher's or subscription's token.
    pub fn endpoint_token(
        &self,
        entity_id: u32,
        kind: Kind,
        qualified: &str,
        type_name: &str,
        hash: &str,
    ) -> String {
        format!(
            "{}/{}/{type_name}/{hash}/{QOS}",
            self.prefix(entity_id, kind.code()),
            mangle(qualified)
        )
    }
}

/// A publisher's GID: 16 bytes unique to the session and the entity.
pub fn gid(session: &[u8; 16], entity_id: u32) -> [u8; 16] {
    let mut g = *session;
    for (b, e) in g[12..].iter_mut().zip(entity_id.to_le_bytes()) {
        *b ^= e;
    }
    g
}

/// The attachment rmw_zenoh puts on (and expects with) every sample.
pub fn attachment(sequence: i64, source_ns: i64, gid: &[u8; 16]) -> Vec<u8> {
    let mut a = Vec::with_capacity(33);
    a.extend_from_slice(&sequence.to_le_bytes());
    a.extend_from_slice(&source_ns.to_le_bytes());
    a.push(16);
    a.extend_from_slice(gid);
    a
}

/// A request's attachment: the client's sequence number, its timestamp
/// and its GID; `None` when it is not in rmw_zenoh's layout.
pub fn parse_attachment(a: &[u8]) -> Option<(i64, i64, [u8; 16])> {
    let [seq, ts] = [&a.get(..8)?, &a.get(8..16)?].map(|b| {
        let mut x = [0u8; 8];
        x.copy_from_slice(b);
        i64::from_le_bytes(x)
    });
    if *a.get(16)? != 16 {
        return None;
    }
    let gid: [u8; 16] = a.get(17..33)?.try_into().ok()?;
    Some((seq, ts, gid))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node() -> NodeIdentity {
        NodeIdentity {
            domain: 2,
            session: "8b20917502ee955ac4476e0266340d5c".into(),
            node_id: 0,
            namespace: String::new(),
            name: "talker".into(),
        }
    }

    #[test]
    fn keys_and_tokens_read_as_the_design_document_prints_them() {
        // The design document's own examples, with String's type and hash.
        let string = (
            "std_msgs::msg::dds_::String_",
            "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
        );
        assert_eq!(
            topic_key(0, &qualified("", "chatter"), string.0, string.1),
            "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
        );
        assert_eq!(
            topic_key(0, &qualified("/robot1", "chatter"), string.0, string.1),
            "0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
        );
        assert_eq!(
            node().endpoint_token(10, Kind::Publisher, "/chatter", string.0, string.1),
            "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
        );
        let listener = NodeIdentity {
            name: "listener".into(),
            session: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
            ..node()
        };
        assert_eq!(
            listener.node_token(),
            "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
        );
        let namespaced = NodeIdentity {
            namespace: "/hand/left".into(),
            ..node()
        };
        assert!(namespaced.node_token().ends_with("/NN/%/%hand%left/talker"));
    }

    #[test]
    fn no_namespace_gives_root_topics_and_tokens() {
        assert_eq!(qualified("", "joint_states"), "/joint_states");
        assert_eq!(qualified("/", "joint_commands"), "/joint_commands");
        assert_eq!(
            topic_key(
                0,
                &qualified("", "joint_states"),
                JOINT_STATE_TYPE,
                JOINT_STATE_HASH
            ),
            format!("0/joint_states/{JOINT_STATE_TYPE}/{JOINT_STATE_HASH}")
        );
        let token = node().endpoint_token(
            1,
            Kind::Subscription,
            &qualified("", "joint_commands"),
            JOINT_STATE_TYPE,
            JOINT_STATE_HASH,
        );
        assert!(token.contains("/MS/%/%/talker/%joint_commands/"), "{token}");
    }

    #[test]
    fn humble_keys_and_tokens_have_no_type_hash() {
        let hash = type_hash(Distro::Humble, JOINT_STATE_HASH);
        assert_eq!(
            topic_key(
                0,
                &qualified("sim0", "joint_states"),
                JOINT_STATE_TYPE,
                hash
            ),
            "0/sim0/joint_states/sensor_msgs::msg::dds_::JointState_/TypeHashNotSupported"
        );
        assert_eq!(
            node().endpoint_token(3, Kind::Service, "/sim0/estop", TRIGGER_TYPE, type_hash(Distro::Humble, TRIGGER_HASH)),
            "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/3/SS/%/%/talker/%sim0%estop/std_srvs::srv::dds_::Trigger_/TypeHashNotSupported/::,10:,:,:,,"
        );
        assert_eq!(type_hash(Distro::Jazzy, SET_BOOL_HASH), SET_BOOL_HASH);
        assert_eq!(
            topic_key(0, "/sim0/enable", SET_BOOL_TYPE, type_hash(Distro::Jazzy, SET_BOOL_HASH)),
            "0/sim0/enable/std_srvs::srv::dds_::SetBool_/RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a"
        );
    }

    #[test]
    fn the_attachment_is_33_bytes_in_the_documented_order() {
        let g = gid(&[7; 16], 3);
        let a = attachment(5, 1_700_000_000_000_000_000, &g);
        assert_eq!(a.len(), 33);
        assert_eq!(&a[..8], &5i64.to_le_bytes());
        assert_eq!(&a[8..16], &1_700_000_000_000_000_000i64.to_le_bytes());
        assert_eq!(a[16], 16);
        assert_eq!(&a[17..], &g);
        assert_ne!(gid(&[7; 16], 3), gid(&[7; 16], 4), "one GID per entity");
        assert_eq!(
            parse_attachment(&a),
            Some((5, 1_700_000_000_000_000_000, g))
        );
        assert_eq!(parse_attachment(&a[..32]), None);
        let mut odd = a.clone();
        odd[16] = 8;
        assert_eq!(parse_attachment(&odd), None);
    }
}
