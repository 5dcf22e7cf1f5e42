//! The hands from the config, checked: a `[[hand]]` names a set of joints,
//! possibly on several buses, each with a joint name; [`resolve`] holds them
//! against the buses there are.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::protocol::ids::parse_id_list;

/// `[[hand]]`: a named set of joints.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandConfig {
    pub name: String,
    pub joints: Vec<HandJoints>,
}

/// Joints of one bus in a hand: `{ bus = "l", ids = "1-8", names = [...] }`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandJoints {
    pub bus: String,
    pub ids: Ids,
    /// One name per id, in order; absent names are `<bus>_<id>`.
    #[serde(default)]
    pub names: Vec<String>,
}

/// An id, a list of ids, or a range spec such as `"1-8"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum Ids {
    One(u8),
    List(Vec<u8>),
    Spec(String),
}

/// One joint of a hand.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct HandJoint {
    pub name: String,
    pub bus: String,
    pub id: u8,
}

/// A hand as the daemon uses it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Hand {
    pub name: String,
    pub joints: Vec<HandJoint>,
}

impl Hand {
    pub fn joint(&self, name: &str) -> Option<&HandJoint> {
        self.joints.iter().find(|j| j.name == name)
    }
}

#[derive(Debug, Error, PartialEq)]
pub enum HandError {
    #[error("[[hand]] #{index}: a hand needs a name")]
    NoName { index: usize },
    #[error("hand `{0}` is named twice")]
    Twice(String),
    #[error("hand `{hand}`: no bus named `{bus}`")]
    UnknownBus { hand: String, bus: String },
    #[error("hand `{hand}`: ids of bus `{bus}`: {why}")]
    Ids {
        hand: String,
        bus: String,
        why: String,
    },
    #[error("hand `{hand}`: {names} names for {ids} ids on bus `{bus}`")]
    Names {
        hand: String,
        bus: String,
        names: usize,
        ids: usize,
    },
    #[error("hand `{hand}`: joint name `{name}` is used twice")]
    NameTwice { hand: String, name: String },
    #[error("hand `{hand}`: joint {id} of bus `{bus}` is listed twice")]
    JointTwice { hand: String, bus: String, id: u8 },
}

/// Checks the configured hands against the buses there are.
pub fn resolve(configs: &[HandConfig], buses: &[String]) -> Result<Vec<Hand>, HandError> {
    let mut hands: Vec<Hand> = Vec::new();
    for (index, c) in configs.iter().enumerate() {
        if c.name.trim().is_empty() {
            return Err(HandError::NoName { index });
        }
        if hands.iter().any(|h| h.name == c.name) {
            return Err(HandError::Twice(c.name.clone()));
        }
        let mut joints: Vec<HandJoint> = Vec::new();
        for part in &c.joints {
            joints_of(c, part, buses, &mut joints)?;
        }
        hands.push(Hand {
            name: c.name.clone(),
            joints,
        });
    }
    Ok(hands)
}

fn joints_of(
    c: &HandConfig,
    part: &HandJoints,
    buses: &[String],
    joints: &mut Vec<HandJoint>,
) -> Result<(), HandError> {
    if !buses.contains(&part.bus) {
        return Err(HandError::UnknownBus {
            hand: c.name.clone(),
            bus: part.bus.clone(),
        });
    }
    let ids = match &part.ids {
        Ids::One(id) => vec![*id],
        Ids::List(ids) => ids.clone(),
        Ids::Spec(spec) => parse_id_list(spec).map_err(|why| HandError::Ids {
            hand: c.name.clone(),
            bus: part.bus.clone(),
            why,
        })?,
    };
    if part.names.len() > ids.len() {
        return Err(HandError::Names {
            hand: c.name.clone(),
            bus: part.bus.clone(),
            names: part.names.len(),
            ids: ids.len(),
        });
    }
    for (k, id) in ids.iter().enumerate() {
        let name = part
            .names
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("{}_{id}", part.bus));
        if joints.iter().any(|j| j.name == name) {
            return Err(HandError::NameTwice {
                hand: c.name.clone(),
                name,
            });
        }
        if joints.iter().any(|j| j.bus == part.bus && j.id == *id) {
            return Err(HandError::JointTwice {
                hand: c.name.clone(),
                bus: part.bus.clone(),
                id: *id,
            });
        }
        joints.push(HandJoint {
            name,
            bus: part.bus.clone(),
            id: *id,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(text: &str) -> Vec<HandConfig> {
        #[derive(Deserialize)]
        struct File {
            hand: Vec<HandConfig>,
        }
        toml::from_str::<File>(text).unwrap().hand
    }

    fn buses() -> Vec<String> {
        vec!["l".into(), "l2".into()]
    }

    #[test]
    fn a_hand_spans_buses_with_names_given_or_made() {
        let hands = resolve(
            &config(
                r#"
                [[hand]]
                name = "left"
                joints = [{ bus = "l", ids = "1-3", names = ["thumb", "index"] },
                          { bus = "l2", ids = [1] }]
                "#,
            ),
            &buses(),
        )
        .unwrap();
        let names: Vec<(&str, &str, u8)> = hands[0]
            .joints
            .iter()
            .map(|j| (j.name.as_str(), j.bus.as_str(), j.id))
            .collect();
        assert_eq!(
            names,
            vec![
                ("thumb", "l", 1),
                ("index", "l", 2),
                ("l_3", "l", 3),
                ("l2_1", "l2", 1)
            ]
        );
    }

    #[test]
    fn bad_hands_are_refused_with_the_reason() {
        let bad = |text: &str| resolve(&config(text), &buses()).unwrap_err();
        assert_eq!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "nope", ids = 1 }]"#),
            HandError::UnknownBus {
                hand: "x".into(),
                bus: "nope".into()
            }
        );
        assert!(matches!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "l", ids = "1-2", names = ["a", "a"] }]"#),
            HandError::NameTwice { .. }
        ));
        assert!(matches!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "l", ids = 1 }, { bus = "l", ids = "1", names = ["other"] }]"#),
            HandError::JointTwice { id: 1, .. }
        ));
        assert!(matches!(
            bad(r#"[[hand]]
name = "x"
joints = [{ bus = "l", ids = "one" }]"#),
            HandError::Ids { .. }
        ));
    }
}
