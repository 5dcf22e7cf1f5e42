//! `sensor_msgs/msg/JointState` in CDR, little-endian, as ROS 2 puts it on
//! the wire (XCDR1 as Fast DDS and rmw_zenoh use it): a 4-byte
//! encapsulation header (`00 01 00 00`), then each field aligned to its own
//! size counted from the end of that header; strings are a u32 length that
//! counts the terminating NUL, the bytes, the NUL; sequences a u32 count,
//! then the elements. Shared by MCAP recordings and the ROS 2 bridge.

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

/// A CDR little-endian writer.
struct Cdr {
    buf: Vec<u8>,
}

/// The encapsulation header: CDR, little-endian, no options.
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

impl Cdr {
    fn new() -> Self {
        Self {
            buf: CDR_LE.to_vec(),
        }
    }

    fn align(&mut self, n: usize) {
        let offset = self.buf.len() - CDR_LE.len();
        let pad = (n - offset % n) % n;
        self.buf.extend(std::iter::repeat(0).take(pad));
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn string(&mut self, s: &str) {
        self.u32(len_u32(s.len() + 1));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    fn f64s(&mut self, v: &[f64]) {
        self.u32(len_u32(v.len()));
        if !v.is_empty() {
            self.align(8);
        }
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }
}

/// A length as CDR's u32 (a message of 4 G elements is not one jointd makes).
fn len_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl JointState {
    /// The message in CDR, encapsulation header first.
    pub fn to_cdr(&self) -> Vec<u8> {
        let mut w = Cdr::new();
        let sec = i32::try_from(self.stamp_ns / 1_000_000_000).unwrap_or(i32::MAX);
        w.i32(sec);
        w.u32((self.stamp_ns % 1_000_000_000) as u32);
        w.string(&self.frame_id);
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

#[cfg(test)]
mod tests {
    use super::*;

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
