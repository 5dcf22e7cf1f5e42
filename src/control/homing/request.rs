//! What a homing job is asked for, and the request checked into the plan
//! every joint of the job follows; no I/O, so each bound is tested here.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::control::error::{ControlError, ControlResult};
use crate::control::joints::JointRef;
use crate::control::limits::JointLimits;
use crate::protocol::units;

/// How far inside the device's ±255° a stop may read (`stop_at_deg`):
/// room for the largest back-off.
const STOP_AT_END_MARGIN_DEG: f64 = 30.0;
/// The largest `max_travel_deg`: the whole angle range.
const MAX_TRAVEL_DEG: f64 = 2.0 * units::MAX_ANGLE_DEG;

/// Which way the joint turns to find its stop (device angles).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub(crate) enum Direction {
    #[default]
    Negative,
    Positive,
}

impl Direction {
    pub(super) fn sign(self) -> f64 {
        match self {
            Self::Negative => -1.0,
            Self::Positive => 1.0,
        }
    }
}

/// One joint to home: by `bus` and `id`, or by `hand` and `joint`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct HomingJoint {
    #[schema(example = "sim0")]
    pub bus: Option<String>,
    #[schema(example = 1)]
    pub id: Option<i64>,
    pub hand: Option<String>,
    pub joint: Option<String>,
}

/// What to home and how. Defaults are gentle: 10 °/s under 0.3 A.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"joints": [{"bus": "sim0", "id": 1}], "direction": "negative",
    "speed_dps": 10.0, "current_limit_a": 0.3, "backoff_deg": 2.0, "stop_at_deg": 0.0, "timeout_ms": 20000}))]
pub(crate) struct HomingRequest {
    /// The joints (or give `hand`).
    pub joints: Option<Vec<HomingJoint>>,
    /// Every joint of this hand.
    pub hand: Option<String>,
    /// Which way (in device angles) the stop lies; default `negative`.
    pub direction: Option<Direction>,
    /// Search speed at the output, °/s (0 < s ≤ 90; default 10).
    #[schema(example = 10.0, exclusive_minimum = 0.0, maximum = 90.0)]
    pub speed_dps: Option<f64>,
    /// Current limit while searching, A (0 < I, below the joint's own
    /// limit; default 0.3).
    #[schema(example = 0.3, exclusive_minimum = 0.0, maximum = 5.625)]
    pub current_limit_a: Option<f64>,
    /// How far to move back off the stop, degrees (0..=30; default 2).
    #[schema(example = 2.0, minimum = 0.0, maximum = 30.0)]
    pub backoff_deg: Option<f64>,
    /// The joint angle the stop reads from then on (default 0). It must
    /// lie within the joint's soft range and at least 30° inside the ±255°
    /// angle range: 422 with the allowed range otherwise.
    #[schema(example = 0.0, minimum = -225.0, maximum = 225.0)]
    pub stop_at_deg: Option<f64>,
    /// The search fails ("no hard stop within ...") after the joint turned
    /// this far from where it started, degrees (0 < d ≤ 510; default: the
    /// width of the joint's soft range). It also fails at the soft limit
    /// in the search direction, whichever comes first.
    #[schema(example = 60.0, exclusive_minimum = 0.0, maximum = 510.0)]
    pub max_travel_deg: Option<f64>,
    /// Give up the search after this long, ms (0 < t ≤ 120000; default 20000).
    #[schema(example = 20000.0, exclusive_minimum = 0.0, maximum = 120000.0)]
    pub timeout_ms: Option<f64>,
}

/// The request checked.
#[derive(Debug, Clone, Copy)]
pub(super) struct Plan {
    pub(super) direction: Direction,
    pub(super) speed_dps: f64,
    pub(super) current_limit_a: f64,
    pub(super) backoff_deg: f64,
    pub(super) stop_at_deg: f64,
    /// `None`: the width of each joint's soft range.
    pub(super) max_travel_deg: Option<f64>,
    pub(super) timeout: Duration,
}

/// The request checked, its defaults filled in.
pub(super) fn plan(req: &HomingRequest) -> ControlResult<Plan> {
    let within =
        |field: &str, v: Option<f64>, default: f64, (lo, hi): (f64, f64), open_low: bool| {
            let x = v.unwrap_or(default);
            let low_ok = if open_low { x > lo } else { x >= lo };
            if x.is_finite() && low_ok && x <= hi {
                Ok(x)
            } else {
                let unit = match field {
                    "speed_dps" => "deg/s",
                    "current_limit_a" => "A",
                    "timeout_ms" => "ms",
                    _ => "deg",
                };
                Err(ControlError::out_of_range(field, x, (lo, hi), unit))
            }
        };
    let max_a = units::current_limit_a(u16::MAX >> 1);
    Ok(Plan {
        direction: req.direction.unwrap_or_default(),
        speed_dps: within("speed_dps", req.speed_dps, 10.0, (0.0, 90.0), true)?,
        current_limit_a: within(
            "current_limit_a",
            req.current_limit_a,
            0.3,
            (0.0, max_a),
            true,
        )?,
        backoff_deg: within("backoff_deg", req.backoff_deg, 2.0, (0.0, 30.0), false)?,
        stop_at_deg: within(
            "stop_at_deg",
            req.stop_at_deg,
            0.0,
            (-units::MAX_ANGLE_DEG, units::MAX_ANGLE_DEG),
            false,
        )?,
        max_travel_deg: req
            .max_travel_deg
            .map(|d| within("max_travel_deg", Some(d), d, (0.0, MAX_TRAVEL_DEG), true))
            .transpose()?,
        timeout: Duration::from_secs_f64(
            within(
                "timeout_ms",
                req.timeout_ms,
                20_000.0,
                (0.0, 120_000.0),
                true,
            )? / 1e3,
        ),
    })
}

/// `stop_at_deg` within the joint's soft range and not at the end of the
/// angle range: a stop reading ±255° leaves no angle beyond it for the
/// back-off, and an offset that puts it there cannot be saved.
pub(super) fn check_stop_at(plan: &Plan, soft: &JointLimits, r: &JointRef) -> ControlResult<()> {
    let lo = soft
        .min_deg
        .max(-units::MAX_ANGLE_DEG + STOP_AT_END_MARGIN_DEG);
    let hi = soft
        .max_deg
        .min(units::MAX_ANGLE_DEG - STOP_AT_END_MARGIN_DEG);
    let x = plan.stop_at_deg;
    if (lo..=hi).contains(&x) {
        return Ok(());
    }
    let err = ControlError::out_of_range("stop_at_deg", x, (lo, hi), "deg").with_detail(format!(
        "stop_at_deg = {x} deg is outside what joint {} of bus `{}` allows, {lo}..={hi} deg: \
         its soft range ({}..={} deg), at least {STOP_AT_END_MARGIN_DEG} deg inside the \
         ±{} deg angle range",
        r.id,
        r.bus,
        soft.min_deg,
        soft.max_deg,
        units::MAX_ANGLE_DEG
    ));
    Err(err)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(json: &str) -> HomingRequest {
        serde_json::from_str(json).expect("a valid request")
    }

    #[test]
    fn an_empty_request_gets_the_gentle_defaults() {
        let p = plan(&request(r#"{"hand": "left"}"#)).expect("defaults are valid");
        assert_eq!(p.direction, Direction::Negative);
        assert_eq!(p.speed_dps, 10.0);
        assert_eq!(p.current_limit_a, 0.3);
        assert_eq!(p.backoff_deg, 2.0);
        assert_eq!(p.stop_at_deg, 0.0);
        assert_eq!(p.max_travel_deg, None);
        assert_eq!(p.timeout, Duration::from_secs(20));
    }

    #[test]
    fn each_bound_is_refused_naming_its_field() {
        for (body, field) in [
            (r#"{"speed_dps": 0}"#, "speed_dps"),
            (r#"{"speed_dps": 90.5}"#, "speed_dps"),
            (r#"{"current_limit_a": 0}"#, "current_limit_a"),
            (r#"{"backoff_deg": -1}"#, "backoff_deg"),
            (r#"{"backoff_deg": 31}"#, "backoff_deg"),
            (r#"{"stop_at_deg": 300}"#, "stop_at_deg"),
            (r#"{"max_travel_deg": 0}"#, "max_travel_deg"),
            (r#"{"max_travel_deg": 511}"#, "max_travel_deg"),
            (r#"{"timeout_ms": 120001}"#, "timeout_ms"),
        ] {
            let err = plan(&request(body)).expect_err(body);
            assert!(err.to_string().contains(field), "{body}: {err}");
        }
    }

    #[test]
    fn the_edges_of_each_range_are_accepted() {
        let p = plan(&request(
            r#"{"speed_dps": 90, "backoff_deg": 0, "max_travel_deg": 510, "timeout_ms": 120000}"#,
        ))
        .expect("the edges are inside");
        assert_eq!(p.speed_dps, 90.0);
        assert_eq!(p.backoff_deg, 0.0);
        assert_eq!(p.max_travel_deg, Some(510.0));
    }

    #[test]
    fn a_stop_must_read_inside_the_soft_range_and_away_from_the_angle_ends() {
        let joint = JointRef {
            bus: "sim0".into(),
            id: 1,
        };
        let wide = JointLimits {
            min_deg: -255.0,
            max_deg: 255.0,
            ..JointLimits::default()
        };
        let at =
            |deg: f64| plan(&request(&format!(r#"{{"stop_at_deg": {deg}}}"#))).expect("in range");
        assert!(check_stop_at(&at(225.0), &wide, &joint).is_ok());
        assert!(check_stop_at(&at(225.5), &wide, &joint).is_err());
        assert!(check_stop_at(&at(-225.5), &wide, &joint).is_err());
        let narrow = JointLimits {
            min_deg: 0.0,
            max_deg: 90.0,
            ..JointLimits::default()
        };
        assert!(check_stop_at(&at(0.0), &narrow, &joint).is_ok());
        assert!(check_stop_at(&at(-1.0), &narrow, &joint).is_err());
    }
}
