//! The messages recordings and the ROS 2 bridge both carry, with the
//! definitions MCAP's schema records and rosbag2 need:
//! `sensor_msgs/msg/JointState`, `std_msgs/msg/String`,
//! `diagnostic_msgs/msg/DiagnosticArray`.

use super::cdr::{len_u32, Cdr, CdrError, CdrReader};

/// The message definition as `ros2msg` (with its dependencies), what MCAP's
/// schema record and rosbag2 expect.
pub const JOINT_STATE_MSG: &str = "\
# jointd: position in rad, velocity in rad/s at the output shaft, effort is
# the q-axis current in A (not a torque).
std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
";

/// One `sensor_msgs/msg/JointState`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointState {
    /// Header stamp: Unix time of the newest sample in it.
    pub stamp_ns: u64,
    pub frame_id: String,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

impl JointState {
    /// The message in CDR, encapsulation header first.
    pub fn to_cdr(&self) -> Vec<u8> {
        let mut w = Cdr::new();
        w.stamp(self.stamp_ns, &self.frame_id);
        w.u32(len_u32(self.name.len()));
        for n in &self.name {
            w.string(n);
        }
        w.f64s(&self.position);
        w.f64s(&self.velocity);
        w.f64s(&self.effort);
        w.buf
    }
}

impl JointState {
    /// A `JointState` from CDR (what a ROS 2 publisher puts on the wire).
    pub fn from_cdr(buf: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(buf)?;
        let sec = r.u32()?;
        let nanosec = r.u32()?;
        let frame_id = r.string()?;
        let names = r.count(4)?;
        let name = (0..names).map(|_| r.string()).collect::<Result<_, _>>()?;
        Ok(Self {
            stamp_ns: u64::from(sec) * 1_000_000_000 + u64::from(nanosec),
            frame_id,
            name,
            position: r.f64s()?,
            velocity: r.f64s()?,
            effort: r.f64s()?,
        })
    }
}

/// `std_msgs/msg/String`'s definition.
pub const STRING_MSG: &str = "string data\n";

/// A `std_msgs/msg/String` in CDR.
pub fn string_cdr(text: &str) -> Vec<u8> {
    let mut w = Cdr::new();
    w.string(text);
    w.buf
}

/// The text of a `std_msgs/msg/String` in CDR.
pub fn string_from_cdr(buf: &[u8]) -> Result<String, CdrError> {
    CdrReader::new(buf)?.string()
}

/// One `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DiagnosticStatus {
    /// 0 OK, 1 WARN, 2 ERROR, 3 STALE.
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<(String, String)>,
}

/// `diagnostic_msgs/msg/DiagnosticArray` in CDR.
pub fn diagnostic_array_cdr(stamp_ns: u64, frame_id: &str, status: &[DiagnosticStatus]) -> Vec<u8> {
    let mut w = Cdr::new();
    w.stamp(stamp_ns, frame_id);
    w.u32(len_u32(status.len()));
    for s in status {
        w.buf.push(s.level);
        w.string(&s.name);
        w.string(&s.message);
        w.string(&s.hardware_id);
        w.u32(len_u32(s.values.len()));
        for (k, v) in &s.values {
            w.string(k);
            w.string(v);
        }
    }
    w.buf
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_joint_state_reads_back_and_garbage_is_refused() {
        let msg = JointState {
            stamp_ns: 12_000_000_345,
            frame_id: "f".into(),
            name: vec!["a".into(), "bcd".into()],
            position: vec![0.5, -1.0],
            velocity: vec![],
            effort: vec![2.0, 3.0],
        };
        let bytes = msg.to_cdr();
        assert_eq!(JointState::from_cdr(&bytes), Ok(msg));
        assert!(JointState::from_cdr(&bytes[..bytes.len() - 3]).is_err());
        assert!(matches!(
            JointState::from_cdr(&[1, 0, 0, 0, 0]),
            Err(CdrError::Encapsulation(_))
        ));
        let mut huge = bytes.clone();
        huge[4 + 16..4 + 20].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(
            JointState::from_cdr(&huge).is_err(),
            "a length past the end"
        );
    }

    #[test]
    fn a_string_message_round_trips() {
        let b = string_cdr("{\"a\":1}");
        assert_eq!(&b[..8], &[0, 1, 0, 0, 8, 0, 0, 0]);
        assert_eq!(string_from_cdr(&b).unwrap(), "{\"a\":1}");
    }

    #[test]
    fn a_diagnostic_array_is_laid_out_as_cdr_says() {
        let status = DiagnosticStatus {
            level: 2,
            name: "n".into(),
            message: String::new(),
            hardware_id: "h".into(),
            values: vec![("k".into(), "v".into())],
        };
        let b = diagnostic_array_cdr(0, "", &[status]);
        let mut want = vec![0, 1, 0, 0];
        want.extend([0; 8]); // stamp
        want.extend(1u32.to_le_bytes()); // frame_id ""
        want.extend([0, 0, 0, 0]);
        want.extend(1u32.to_le_bytes()); // 16: one status
        want.push(2); // 20: level
        want.extend([0, 0, 0]); // to 24
        want.extend(2u32.to_le_bytes());
        want.extend(b"n\0\0\0"); // 28..32
        want.extend(1u32.to_le_bytes()); // message ""
        want.extend([0, 0, 0, 0]);
        want.extend(2u32.to_le_bytes());
        want.extend(b"h\0\0\0");
        want.extend(1u32.to_le_bytes()); // one value
        want.extend(2u32.to_le_bytes());
        want.extend(b"k\0\0\0");
        want.extend(2u32.to_le_bytes());
        want.extend(b"v\0");
        assert_eq!(b, want);
    }

    #[test]
    fn a_joint_state_is_laid_out_as_cdr_says() {
        let msg = JointState {
            stamp_ns: 1_700_000_000_250_000_000,
            frame_id: String::new(),
            name: vec!["ab".into()],
            position: vec![1.5],
            velocity: vec![],
            effort: vec![-0.25],
        };
        // Offsets after the encapsulation header.
        let mut want = vec![0, 1, 0, 0];
        want.extend(1_700_000_000i32.to_le_bytes()); // 0: sec
        want.extend(250_000_000u32.to_le_bytes()); // 4: nanosec
        want.extend(1u32.to_le_bytes()); // 8: frame_id "" is one NUL
        want.extend([0, 0, 0, 0]); // 12: the NUL, padding to 16
        want.extend(1u32.to_le_bytes()); // 16: one name
        want.extend(3u32.to_le_bytes()); // 20: "ab" and its NUL
        want.extend(b"ab\0\0"); // 24: and a byte of padding
        want.extend(1u32.to_le_bytes()); // 28: one position
        want.extend(1.5f64.to_le_bytes()); // 32: already 8-aligned
        want.extend(0u32.to_le_bytes()); // 40: no velocity
        want.extend(1u32.to_le_bytes()); // 44: one effort
        want.extend((-0.25f64).to_le_bytes()); // 48
        assert_eq!(msg.to_cdr(), want);

        let odd = JointState {
            frame_id: "x".into(),
            position: vec![2.0],
            ..JointState::default()
        };
        let b = odd.to_cdr();
        // 8: len 2, 12: "x\0", pad to 16: names 0; 20: positions 1; 24: f64.
        assert_eq!(&b[4 + 20..4 + 24], &1u32.to_le_bytes());
        assert_eq!(&b[4 + 24..4 + 32], &2.0f64.to_le_bytes());
    }
}
