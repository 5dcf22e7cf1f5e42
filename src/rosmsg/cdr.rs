//! CDR little-endian, as ROS 2 puts messages on the wire (XCDR1 as Fast
//! DDS and rmw_zenoh use it): a 4-byte encapsulation header
//! (`00 01 00 00`), then each field aligned to its own size counted from
//! the end of that header; strings are a u32 length that counts the
//! terminating NUL, the bytes, the NUL; sequences a u32 count, then the
//! elements. The writer and its mirror, the reader; no message here.

/// A CDR little-endian writer (the ROS 2 bridge's messages use it too).
pub(crate) struct Cdr {
    pub(crate) buf: Vec<u8>,
}

/// The encapsulation header: CDR, little-endian, no options.
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

impl Cdr {
    pub(crate) fn new() -> Self {
        Self {
            buf: CDR_LE.to_vec(),
        }
    }

    fn align(&mut self, n: usize) {
        let offset = self.buf.len() - CDR_LE.len();
        let pad = (n - offset % n) % n;
        self.buf.extend(std::iter::repeat(0).take(pad));
    }

    pub(crate) fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn string(&mut self, s: &str) {
        self.u32(len_u32(s.len() + 1));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// Only test senders write a lone double (no message jointd sends has one).
    #[cfg(test)]
    pub(crate) fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f64s(&mut self, v: &[f64]) {
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
pub(crate) fn len_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl Cdr {
    pub(crate) fn stamp(&mut self, stamp_ns: u64, frame_id: &str) {
        let sec = i32::try_from(stamp_ns / 1_000_000_000).unwrap_or(i32::MAX);
        self.i32(sec);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame_id);
    }
}

/// Why bytes are not the message they claim to be.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    #[error("not CDR little-endian (encapsulation {0:02X?})")]
    Encapsulation([u8; 4]),
    #[error("cut short at byte {0}")]
    Short(usize),
    #[error("a string that is not UTF-8 or not NUL-terminated at byte {0}")]
    BadString(usize),
    #[error("a sequence of {0} elements does not fit in the message")]
    TooLong(u32),
}

/// A CDR little-endian reader (the writer's mirror).
pub(crate) struct CdrReader<'a> {
    buf: &'a [u8],
    at: usize,
}

impl<'a> CdrReader<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Result<Self, CdrError> {
        let head: [u8; 4] = buf
            .get(..4)
            .and_then(|h| h.try_into().ok())
            .ok_or(CdrError::Short(0))?;
        // CDR_LE, or PL_CDR_LE (options bytes are ignored).
        if head[0] != 0 || (head[1] != 1 && head[1] != 3) {
            return Err(CdrError::Encapsulation(head));
        }
        Ok(Self { buf, at: 4 })
    }

    fn align(&mut self, n: usize) {
        let offset = self.at - CDR_LE.len();
        self.at += (n - offset % n) % n;
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], CdrError> {
        let out = self
            .buf
            .get(self.at..self.at + n)
            .ok_or(CdrError::Short(self.at))?;
        self.at += n;
        Ok(out)
    }

    pub(crate) fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.take(1)?[0])
    }

    pub(crate) fn i32(&mut self) -> Result<i32, CdrError> {
        Ok(self.u32()? as i32)
    }

    pub(crate) fn u32(&mut self) -> Result<u32, CdrError> {
        self.align(4);
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A sequence's length, refused when `elem`-byte elements could not fit.
    pub(crate) fn count(&mut self, elem: usize) -> Result<usize, CdrError> {
        let n = self.u32()?;
        let left = self.buf.len().saturating_sub(self.at);
        if (n as usize).saturating_mul(elem.max(1)) > left {
            return Err(CdrError::TooLong(n));
        }
        Ok(n as usize)
    }

    pub(crate) fn string(&mut self) -> Result<String, CdrError> {
        let n = self.count(1)?;
        let at = self.at;
        let bytes = self.take(n)?;
        match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString(at)),
            _ => Err(CdrError::BadString(at)),
        }
    }

    pub(crate) fn f64(&mut self) -> Result<f64, CdrError> {
        self.align(8);
        let b = self.take(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(f64::from_le_bytes(a))
    }

    pub(crate) fn f64s(&mut self) -> Result<Vec<f64>, CdrError> {
        let n = self.count(8)?;
        if n > 0 {
            self.align(8);
        }
        (0..n)
            .map(|_| {
                let b = self.take(8)?;
                let mut a = [0u8; 8];
                a.copy_from_slice(b);
                Ok(f64::from_le_bytes(a))
            })
            .collect()
    }
}
