//! The ROS 2 messages the bridge takes and gives besides `JointState` and
//! `DiagnosticArray` (those are [`super::topics`], shared with
//! recordings), in CDR as rmw_zenoh carries them: the requests and
//! responses of `std_srvs/srv/SetBool` and `std_srvs/srv/Trigger`,
//! `trajectory_msgs/msg/JointTrajectory`, `rcl_interfaces/msg/Log`,
//! `control_msgs/msg/GripperCommand`.
//! Pure: bytes in, bytes out.

use super::cdr::{Cdr, CdrError, CdrReader};

/// `rcl_interfaces/msg/Log`'s level WARN.
pub(crate) const LOG_WARN: u8 = 30;

/// `std_srvs/srv/SetBool`'s request: its `data`.
pub(crate) fn set_bool_request(buf: &[u8]) -> Result<bool, CdrError> {
    let mut r = CdrReader::new(buf)?;
    Ok(r.u8()? != 0)
}

/// `std_srvs/srv/Trigger`'s request has no field (its CDR carries one
/// placeholder byte): only the encapsulation is checked.
pub(crate) fn trigger_request(buf: &[u8]) -> Result<(), CdrError> {
    CdrReader::new(buf).map(drop)
}

/// The response of `SetBool` and of `Trigger` (the same two fields).
pub(crate) fn service_response(success: bool, message: &str) -> Vec<u8> {
    let mut w = Cdr::new();
    w.u8(u8::from(success));
    w.string(message);
    w.buf
}

/// One `trajectory_msgs/msg/JointTrajectoryPoint`.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct TrajectoryPoint {
    pub(crate) positions: Vec<f64>,
    pub(crate) velocities: Vec<f64>,
    pub(crate) accelerations: Vec<f64>,
    pub(crate) effort: Vec<f64>,
    /// `time_from_start`, ns (negative if the sender says so).
    pub(crate) time_from_start_ns: i64,
}

/// One `trajectory_msgs/msg/JointTrajectory`.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct JointTrajectory {
    pub(crate) stamp_ns: i64,
    pub(crate) frame_id: String,
    pub(crate) joint_names: Vec<String>,
    pub(crate) points: Vec<TrajectoryPoint>,
}

impl JointTrajectory {
    pub(crate) fn from_cdr(buf: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(buf)?;
        let stamp_ns = time_ns(&mut r)?;
        let frame_id = r.string()?;
        let names = r.count(4)?;
        let joint_names = (0..names).map(|_| r.string()).collect::<Result<_, _>>()?;
        // A point is at least four counts and a duration: 24 bytes.
        let points = r.count(24)?;
        let points = (0..points)
            .map(|_| {
                Ok(TrajectoryPoint {
                    positions: r.f64s()?,
                    velocities: r.f64s()?,
                    accelerations: r.f64s()?,
                    effort: r.f64s()?,
                    time_from_start_ns: time_ns(&mut r)?,
                })
            })
            .collect::<Result<_, CdrError>>()?;
        Ok(Self {
            stamp_ns,
            frame_id,
            joint_names,
            points,
        })
    }

    /// The message in CDR (what a ROS 2 publisher sends).
    #[cfg(test)]
    pub(crate) fn to_cdr(&self) -> Vec<u8> {
        let mut w = Cdr::new();
        w.u32(self.stamp_ns.div_euclid(1_000_000_000) as u32);
        w.u32(self.stamp_ns.rem_euclid(1_000_000_000) as u32);
        w.string(&self.frame_id);
        w.u32(self.joint_names.len() as u32);
        for n in &self.joint_names {
            w.string(n);
        }
        w.u32(self.points.len() as u32);
        for p in &self.points {
            for v in [&p.positions, &p.velocities, &p.accelerations, &p.effort] {
                w.f64s(v);
            }
            w.u32(p.time_from_start_ns.div_euclid(1_000_000_000) as u32);
            w.u32(p.time_from_start_ns.rem_euclid(1_000_000_000) as u32);
        }
        w.buf
    }
}

/// A `builtin_interfaces` `Time` or `Duration` (int32 sec, uint32 nanosec), ns.
fn time_ns(r: &mut CdrReader<'_>) -> Result<i64, CdrError> {
    let sec = r.i32()?;
    let nanosec = r.u32()?;
    Ok(i64::from(sec) * 1_000_000_000 + i64::from(nanosec))
}

/// One `control_msgs/msg/GripperCommand`: two float64, nothing else.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct GripperCommand {
    /// Where the fingers close to, rad (NaN: each finger's default).
    pub(crate) position: f64,
    /// The hold current, A (effort is a q current throughout the bridge).
    pub(crate) max_effort: f64,
}

impl GripperCommand {
    pub(crate) fn from_cdr(buf: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(buf)?;
        Ok(Self {
            position: r.f64()?,
            max_effort: r.f64()?,
        })
    }

    /// The message in CDR (what a ROS 2 publisher sends).
    #[cfg(test)]
    pub(crate) fn to_cdr(self) -> Vec<u8> {
        let mut w = Cdr::new();
        w.f64(self.position);
        w.f64(self.max_effort);
        w.buf
    }
}

/// One `rcl_interfaces/msg/Log` (what `/rosout` carries).
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct Log {
    pub(crate) stamp_ns: u64,
    pub(crate) level: u8,
    /// The logger's name (the node's).
    pub(crate) name: String,
    pub(crate) msg: String,
    pub(crate) file: String,
    pub(crate) function: String,
    pub(crate) line: u32,
}

impl Log {
    pub(crate) fn to_cdr(&self) -> Vec<u8> {
        let mut w = Cdr::new();
        let sec = i32::try_from(self.stamp_ns / 1_000_000_000).unwrap_or(i32::MAX);
        w.u32(sec as u32);
        w.u32((self.stamp_ns % 1_000_000_000) as u32);
        w.u8(self.level);
        for s in [&self.name, &self.msg, &self.file, &self.function] {
            w.string(s);
        }
        w.u32(self.line);
        w.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_requests_and_responses_are_laid_out_as_cdr_says() {
        assert_eq!(set_bool_request(&[0, 1, 0, 0, 1]), Ok(true));
        assert_eq!(set_bool_request(&[0, 1, 0, 0, 0]), Ok(false));
        assert!(set_bool_request(&[0, 1, 0, 0]).is_err(), "no data");
        assert!(trigger_request(&[0, 1, 0, 0, 0]).is_ok());
        assert!(trigger_request(&[7]).is_err());
        let mut want = vec![0, 1, 0, 0, 1, 0, 0, 0]; // success, padding to 4
        want.extend(3u32.to_le_bytes());
        want.extend(b"ok\0");
        assert_eq!(service_response(true, "ok"), want);
    }

    #[test]
    fn a_trajectory_reads_back_and_a_short_one_is_refused() {
        let t = JointTrajectory {
            stamp_ns: 5_000_000_001,
            frame_id: "f".into(),
            joint_names: vec!["a".into(), "bc".into()],
            points: vec![
                TrajectoryPoint {
                    positions: vec![0.5, -0.5],
                    time_from_start_ns: 500_000_000,
                    ..TrajectoryPoint::default()
                },
                TrajectoryPoint {
                    positions: vec![1.0, 0.0],
                    velocities: vec![0.0, 0.0],
                    time_from_start_ns: 1_500_000_000,
                    ..TrajectoryPoint::default()
                },
            ],
        };
        let b = t.to_cdr();
        assert_eq!(JointTrajectory::from_cdr(&b), Ok(t));
        assert!(JointTrajectory::from_cdr(&b[..b.len() - 1]).is_err());
    }

    #[test]
    fn a_gripper_command_is_two_aligned_doubles() {
        let mut b = vec![0, 1, 0, 0];
        b.extend(0.5f64.to_le_bytes()); // 0: position, already 8-aligned
        b.extend(0.2f64.to_le_bytes()); // 8: max_effort
        let cmd = GripperCommand {
            position: 0.5,
            max_effort: 0.2,
        };
        assert_eq!(cmd.to_cdr(), b);
        assert_eq!(GripperCommand::from_cdr(&b), Ok(cmd));
        let nan = GripperCommand::from_cdr(
            &GripperCommand {
                position: f64::NAN,
                max_effort: -1.0,
            }
            .to_cdr(),
        )
        .unwrap();
        assert!(nan.position.is_nan() && nan.max_effort == -1.0);
        assert_eq!(
            GripperCommand::from_cdr(&b[..19]),
            Err(CdrError::Short(12)),
            "cut short in max_effort"
        );
        assert!(GripperCommand::from_cdr(&[0, 1, 0, 0]).is_err(), "empty");
        assert!(matches!(
            GripperCommand::from_cdr(&[1, 0, 0, 0, 0, 0, 0, 0]),
            Err(CdrError::Encapsulation(_))
        ));
    }

    #[test]
    fn a_log_is_laid_out_as_cdr_says() {
        let log = Log {
            stamp_ns: 2_000_000_003,
            level: LOG_WARN,
            name: "j".into(),
            msg: "m".into(),
            line: 7,
            ..Log::default()
        };
        let mut want = vec![0, 1, 0, 0];
        want.extend(2i32.to_le_bytes()); // 0: sec
        want.extend(3u32.to_le_bytes()); // 4: nanosec
        want.extend([30, 0, 0, 0]); // 8: level, padding to 12
        want.extend(2u32.to_le_bytes()); // 12: name
        want.extend(b"j\0\0\0"); // 16
        want.extend(2u32.to_le_bytes()); // 20: msg
        want.extend(b"m\0\0\0"); // 24
        want.extend(1u32.to_le_bytes()); // 28: file ""
        want.extend([0, 0, 0, 0]); // 32
        want.extend(1u32.to_le_bytes()); // 36: function ""
        want.extend([0, 0, 0, 0]); // 40
        want.extend(7u32.to_le_bytes()); // 44: line
        assert_eq!(log.to_cdr(), want);
    }
}
