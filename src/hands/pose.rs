//! A pose: joint angles (degrees) by joint name. JSON lets an object name a
//! key twice and serde's maps keep the last, so `{"thumb": 10, "thumb": 90}`
//! would save 90 with no word said; a pose given in a request is read with
//! [`unique`], which refuses a joint named twice as a struct refuses a field
//! given twice.

use std::collections::BTreeMap;
use std::fmt;

use serde::de::{self, Deserializer, MapAccess, Visitor};
use serde::Deserialize;

/// Degrees by joint name.
pub type Pose = BTreeMap<String, f64>;

/// `deserialize_with` for an optional pose: `null` or absent is `None`, a
/// joint named twice is an error naming it.
pub fn unique<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Pose>, D::Error> {
    Ok(Option::<UniquePose>::deserialize(d)?.map(|p| p.0))
}

struct UniquePose(Pose);

impl<'de> Deserialize<'de> for UniquePose {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_map(UniqueVisitor)
    }
}

struct UniqueVisitor;

impl<'de> Visitor<'de> for UniqueVisitor {
    type Value = UniquePose;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object of joint names and degrees, each joint once")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<UniquePose, A::Error> {
        let mut pose = Pose::new();
        while let Some(joint) = map.next_key::<String>()? {
            if pose.contains_key(&joint) {
                return Err(de::Error::custom(format_args!(
                    "joint `{joint}` is given twice"
                )));
            }
            let deg = map.next_value::<f64>()?;
            pose.insert(joint, deg);
        }
        Ok(UniquePose(pose))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize)]
    struct Body {
        #[serde(default, deserialize_with = "unique")]
        positions_deg: Option<Pose>,
    }

    fn read(text: &str) -> Result<Option<Pose>, String> {
        serde_json::from_str::<Body>(text)
            .map(|b| b.positions_deg)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn a_joint_named_twice_is_refused_by_name() {
        let err = read(r#"{"positions_deg": {"thumb": 1, "index": 2, "thumb": 3}}"#).unwrap_err();
        assert!(err.contains("joint `thumb` is given twice"), "{err}");
    }

    #[test]
    fn each_joint_once_absent_or_null_read_as_before() {
        let pose = read(r#"{"positions_deg": {"thumb": 1, "index": 2.5}}"#).unwrap();
        assert_eq!(
            pose,
            Some(Pose::from([("thumb".into(), 1.0), ("index".into(), 2.5)]))
        );
        assert_eq!(read("{}").unwrap(), None);
        assert_eq!(read(r#"{"positions_deg": null}"#).unwrap(), None);
        assert!(read(r#"{"positions_deg": {"thumb": "x"}}"#).is_err());
    }
}
