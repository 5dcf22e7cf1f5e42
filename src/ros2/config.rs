//! `[ros2]` in the config file (and `--ros2`, `--ros2-connect`,
//! `--ros2-domain-id`): off unless asked.

use std::collections::BTreeMap;

use serde::Deserialize;
use thiserror::Error;

/// The router rmw_zenoh's nodes use by default.
pub const DEFAULT_ROUTER: &str = "tcp/127.0.0.1:7447";

/// How the bridge joins the Zenoh network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ros2Mode {
    /// Through a router (`zenohd`, `ros2 run rmw_zenoh_cpp rmw_zenohd`), as
    /// rmw_zenoh's nodes do.
    #[default]
    Client,
    /// Directly with other peers (listening on `listen`).
    Peer,
}

/// What a namespace groups.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NamespaceBy {
    /// Every joint of a bus.
    #[default]
    Bus,
    /// A named hand's joints, on one bus or several; joints in no hand
    /// are not bridged.
    Hand,
}

/// The ROS 2 distribution the bridge's keys and tokens are written for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Distro {
    /// Jazzy (and later): each type's RIHS01 hash in keys and tokens.
    #[default]
    Jazzy,
    /// Humble: no type hashes; rmw_zenoh writes `TypeHashNotSupported`.
    Humble,
}

/// `[ros2]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Config {
    #[serde(default)]
    pub enabled: bool,
    #[serde(default)]
    pub mode: Ros2Mode,
    /// Zenoh endpoints to connect to (default: the local router).
    #[serde(default)]
    pub connect: Vec<String>,
    /// Zenoh endpoints to listen on (peer mode).
    #[serde(default)]
    pub listen: Vec<String>,
    /// The ROS domain (default: `ROS_DOMAIN_ID`, else 0).
    pub domain_id: Option<u32>,
    /// Topics per bus (default) or per named hand (`[[hand]]`): each has
    /// `/<namespace>/joint_states` and `/<namespace>/joint_commands`.
    #[serde(default)]
    pub namespace_by: NamespaceBy,
    /// bus (or hand) → namespace; default: its name. `""` (or `"/"`): none,
    /// plain `/joint_states` and `/joint_commands` as `robot_state_publisher`
    /// and `topic_based_ros2_control` expect them.
    #[serde(default)]
    pub namespaces: BTreeMap<String, String>,
    /// How often `/diagnostics` is published, Hz (0 < r ≤ 50; default 1).
    #[serde(default = "one_hz")]
    pub diagnostics_hz: f64,
    /// At most this many `joint_states` per second per namespace (a slow
    /// link's cap); absent: every poll round (the telemetry rate).
    pub joint_states_max_hz: Option<f64>,
    /// The ROS node the topics belong to (default `jointd`).
    #[serde(default = "default_node")]
    pub node_name: String,
    /// Whose key form (default `jazzy`; `humble` has no type hashes).
    #[serde(default)]
    pub distro: Distro,
    /// How fast a hand's fingers close on a `gripper_command`, output °/s
    /// (0 < s <= 180; default 30): `control_msgs/msg/GripperCommand` has
    /// no speed of its own.
    #[serde(default = "default_grasp_speed")]
    pub grasp_speed_dps: f64,
}

fn one_hz() -> f64 {
    1.0
}

fn default_grasp_speed() -> f64 {
    30.0
}

fn default_node() -> String {
    "jointd".into()
}

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            enabled: false,
            mode: Ros2Mode::Client,
            connect: Vec::new(),
            listen: Vec::new(),
            domain_id: None,
            namespace_by: NamespaceBy::Bus,
            namespaces: BTreeMap::new(),
            diagnostics_hz: one_hz(),
            joint_states_max_hz: None,
            node_name: default_node(),
            distro: Distro::Jazzy,
            grasp_speed_dps: default_grasp_speed(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Error)]
pub enum Ros2ConfigError {
    #[error("[ros2] namespaces: no {by} named `{name}`")]
    UnknownName { by: &'static str, name: String },
    #[error("[ros2] `{name}` = `{value}`: {why}")]
    BadName {
        name: &'static str,
        value: String,
        why: &'static str,
    },
    #[error("[ros2] namespaces: {by}s `{first}` and `{second}` would share the namespace `/{namespace}` (their joint_states would interleave and each take the other's commands): give each its own")]
    SharedNamespace {
        by: &'static str,
        first: String,
        second: String,
        namespace: String,
    },
    #[error("[ros2] diagnostics_hz = {0}: give 0 < rate <= 50")]
    Rate(f64),
    #[error(
        "[ros2] joint_states_max_hz = {0}: give a rate above 0 (or leave it out: every poll round)"
    )]
    StatesRate(f64),
    #[error("[ros2] domain_id = {0}: ROS domains are 0..=232")]
    Domain(u32),
    #[error("[ros2] grasp_speed_dps = {0}: give 0 < speed <= 180 (output degrees per second)")]
    GraspSpeed(f64),
}

/// A ROS name token: letters, digits, `_`, not starting with a digit.
fn is_token(s: &str) -> bool {
    !s.is_empty()
        && !s.starts_with(|c: char| c.is_ascii_digit())
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl Ros2Config {
    /// Checks names and rates against the buses (or hands) there are.
    pub fn checked(self, buses: &[String], hands: &[String]) -> Result<Self, Ros2ConfigError> {
        let (by, known) = match self.namespace_by {
            NamespaceBy::Bus => ("bus", buses),
            NamespaceBy::Hand => ("hand", hands),
        };
        for (name, ns) in &self.namespaces {
            if !known.contains(name) {
                return Err(Ros2ConfigError::UnknownName {
                    by,
                    name: name.clone(),
                });
            }
            let ns = ns.trim_matches('/');
            // Empty: topics at the root.
            let ok = ns.is_empty() || ns.split('/').all(is_token);
            if !ok {
                return Err(Ros2ConfigError::BadName {
                    name: "namespaces",
                    value: ns.to_owned(),
                    why: "a ROS namespace is tokens of letters, digits and `_` separated by `/`",
                });
            }
        }
        self.distinct_namespaces(by, known)?;
        if !is_token(&self.node_name) {
            return Err(Ros2ConfigError::BadName {
                name: "node_name",
                value: self.node_name.clone(),
                why: "a ROS node name is letters, digits and `_`, not starting with a digit",
            });
        }
        if !(self.diagnostics_hz.is_finite()
            && self.diagnostics_hz > 0.0
            && self.diagnostics_hz <= 50.0)
        {
            return Err(Ros2ConfigError::Rate(self.diagnostics_hz));
        }
        if let Some(r) = self
            .joint_states_max_hz
            .filter(|r| !(r.is_finite() && *r > 0.0))
        {
            return Err(Ros2ConfigError::StatesRate(r));
        }
        if let Some(d) = self.domain_id.filter(|d| *d > 232) {
            return Err(Ros2ConfigError::Domain(d));
        }
        let s = self.grasp_speed_dps;
        if !(s.is_finite() && s > 0.0 && s <= 180.0) {
            return Err(Ros2ConfigError::GraspSpeed(s));
        }
        Ok(self)
    }

    /// Refuses two buses (or hands) under one namespace.
    fn distinct_namespaces(
        &self,
        by: &'static str,
        known: &[String],
    ) -> Result<(), Ros2ConfigError> {
        let mut seen: BTreeMap<String, &String> = BTreeMap::new();
        for name in known {
            let namespace = self.namespace(name);
            if let Some(first) = seen.insert(namespace.clone(), name) {
                return Err(Ros2ConfigError::SharedNamespace {
                    by,
                    first: first.clone(),
                    second: name.clone(),
                    namespace,
                });
            }
        }
        Ok(())
    }

    /// The namespace of a bus (or hand), without slashes at either end.
    pub fn namespace(&self, name: &str) -> String {
        self.namespaces
            .get(name)
            .map_or(name, String::as_str)
            .trim_matches('/')
            .to_owned()
    }

    /// The domain: the config's, else `ROS_DOMAIN_ID`, else 0.
    pub fn domain(&self) -> u32 {
        self.domain_id
            .or_else(|| std::env::var("ROS_DOMAIN_ID").ok()?.parse().ok())
            .unwrap_or(0)
    }

    /// Where to connect: as configured, else the local router in client mode.
    pub fn endpoints(&self) -> Vec<String> {
        if self.connect.is_empty() && self.mode == Ros2Mode::Client {
            vec![DEFAULT_ROUTER.to_owned()]
        } else {
            self.connect.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Ros2Config, toml::de::Error> {
        toml::from_str(text)
    }

    #[test]
    fn defaults_a_namespace_per_bus_and_the_local_router() {
        let cfg = parse("enabled = true").unwrap();
        assert_eq!(cfg.namespace("sim0"), "sim0");
        assert_eq!(cfg.endpoints(), vec![DEFAULT_ROUTER.to_string()]);
        assert_eq!(cfg.node_name, "jointd");
        assert_eq!(cfg.distro, Distro::Jazzy);
        assert_eq!(cfg.grasp_speed_dps, 30.0);
        assert_eq!(parse("distro = \"humble\"").unwrap().distro, Distro::Humble);
        assert!(
            parse("distro = \"iron\"").is_err(),
            "only the forms written"
        );
        let peer = parse("mode = \"peer\"\nlisten = [\"tcp/0.0.0.0:7450\"]").unwrap();
        assert!(
            peer.endpoints().is_empty(),
            "a peer connects to nobody unless told"
        );
        let named = parse("[namespaces]\nl = \"/hand/left/\"").unwrap();
        assert_eq!(named.namespace("l"), "hand/left");
    }

    #[test]
    fn bad_names_rates_and_buses_are_refused() {
        let buses = vec!["l".to_string()];
        let hands = vec!["left".to_string()];
        let bad = |text: &str| parse(text).unwrap().checked(&buses, &hands).unwrap_err();
        assert_eq!(
            bad("[namespaces]\nr = \"x\""),
            Ros2ConfigError::UnknownName {
                by: "bus",
                name: "r".into()
            }
        );
        assert_eq!(
            bad("namespace_by = \"hand\"\n[namespaces]\nl = \"x\""),
            Ros2ConfigError::UnknownName {
                by: "hand",
                name: "l".into()
            }
        );
        assert!(parse("namespace_by = \"hand\"\n[namespaces]\nleft = \"x\"")
            .unwrap()
            .checked(&buses, &hands)
            .is_ok());
        assert!(matches!(
            bad("[namespaces]\nl = \"a b\""),
            Ros2ConfigError::BadName { .. }
        ));
        assert!(matches!(
            bad("node_name = \"9x\""),
            Ros2ConfigError::BadName { .. }
        ));
        assert_eq!(bad("diagnostics_hz = 0.0"), Ros2ConfigError::Rate(0.0));
        assert_eq!(bad("domain_id = 300"), Ros2ConfigError::Domain(300));
        assert_eq!(
            bad("joint_states_max_hz = -1.0"),
            Ros2ConfigError::StatesRate(-1.0)
        );
        assert_eq!(
            bad("grasp_speed_dps = 0.0"),
            Ros2ConfigError::GraspSpeed(0.0)
        );
        assert_eq!(
            bad("grasp_speed_dps = 200.0"),
            Ros2ConfigError::GraspSpeed(200.0)
        );
        assert!(parse("nope = 1").is_err(), "unknown keys are refused");
        assert!(matches!(
            bad("[namespaces]\nl = \"a//b\""),
            Ros2ConfigError::BadName { .. }
        ));
        assert!(parse("[namespaces]\nl = \"hand/left\"")
            .unwrap()
            .checked(&buses, &hands)
            .is_ok());
    }

    #[test]
    fn an_empty_namespace_gives_topics_at_the_root() {
        let buses = vec!["l".to_string(), "r".to_string()];
        for empty in ["\"\"", "\"/\""] {
            let cfg = parse(&format!("[namespaces]\nl = {empty}"))
                .unwrap()
                .checked(&buses, &[])
                .unwrap();
            assert_eq!(cfg.namespace("l"), "");
            assert_eq!(cfg.namespace("r"), "r");
            assert_eq!(
                super::super::keys::qualified(&cfg.namespace("l"), "joint_states"),
                "/joint_states"
            );
        }
    }

    #[test]
    fn two_buses_may_not_share_a_namespace() {
        let buses = vec!["l".to_string(), "r".to_string()];
        let err = parse("[namespaces]\nl = \"\"\nr = \"/\"")
            .unwrap()
            .checked(&buses, &[])
            .unwrap_err();
        assert_eq!(
            err,
            Ros2ConfigError::SharedNamespace {
                by: "bus",
                first: "l".into(),
                second: "r".into(),
                namespace: String::new(),
            }
        );
        assert!(err.to_string().contains("`l` and `r`"), "{err}");
        // A bus mapped onto another's default name collides too.
        let err = parse("[namespaces]\nl = \"r\"")
            .unwrap()
            .checked(&buses, &[])
            .unwrap_err();
        assert!(
            matches!(err, Ros2ConfigError::SharedNamespace { ref namespace, .. } if namespace == "r"),
            "{err}"
        );
        let hands = vec!["left".to_string(), "right".to_string()];
        let err = parse("namespace_by = \"hand\"\n[namespaces]\nleft = \"x\"\nright = \"/x/\"")
            .unwrap()
            .checked(&buses, &hands)
            .unwrap_err();
        assert!(
            err.to_string()
                .starts_with("[ros2] namespaces: hands `left` and `right`"),
            "{err}"
        );
    }
}
