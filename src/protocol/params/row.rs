//! The shape of a row of the parameter table: the small enums that
//! describe an index, and [`ParamRow`] itself.

use super::scale::Scale;
use crate::protocol::units::UnitError;
use crate::protocol::values::InfoBlock;

/// The protocol revision that introduced a row (SPEC marks rev 2.0.8 facts).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Revision {
    V2_0_1,
    V2_0_8,
}

impl Revision {
    /// Every revision, oldest first.
    pub const ALL: [Revision; 2] = [Self::V2_0_1, Self::V2_0_8];

    pub fn as_str(self) -> &'static str {
        match self {
            Self::V2_0_1 => "2.0.1",
            Self::V2_0_8 => "2.0.8",
        }
    }

    /// `"2.0.1"` or `"2.0.8"` (a leading `v`/`V` is accepted).
    pub fn parse(text: &str) -> Result<Self, UnknownRevision> {
        let t = text.trim();
        let bare = t.strip_prefix(['v', 'V']).unwrap_or(t);
        Self::ALL
            .into_iter()
            .find(|r| r.as_str() == bare)
            .ok_or_else(|| UnknownRevision(t.to_owned()))
    }
}

impl std::fmt::Display for Revision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Revision {
    type Err = UnknownRevision;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::parse(s)
    }
}

/// A revision name no [`Revision`] has.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a protocol revision (known: 2.0.1, 2.0.8)")]
pub struct UnknownRevision(pub String);

/// Whether the host reads an INFO block with the index or writes a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    Read,
    Write,
}

impl Access {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Read => "read",
            Self::Write => "write",
        }
    }
}

/// What the value bytes `data[4..6]` of the config frame carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RawType {
    /// No value: the index alone is the request.
    None,
    U8,
    U16,
}

impl RawType {
    /// The largest raw value the type carries.
    pub const fn max(self) -> u16 {
        match self {
            Self::None => 0,
            Self::U8 => u8::MAX as u16,
            Self::U16 => u16::MAX,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::U8 => "u8",
            Self::U16 => "u16",
        }
    }
}

/// What the device answers to a config frame with this index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReplyKind {
    /// Nothing: only a read-back (if any) shows the write took effect.
    None,
    /// A RES byte (1 success, 0 failure) with the request's index.
    Res,
    /// The INFO block of this index.
    Info,
}

impl ReplyKind {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Res => "res",
            Self::Info => "info",
        }
    }
}

/// Where a written value shows in an INFO block: the read-back a write is
/// verified by and the bytes the simulator reports it in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Field {
    pub block: InfoBlock,
    /// Offset in the block's 8 data bytes.
    pub at: usize,
    /// `U8` or `U16` (little-endian).
    pub width: RawType,
}

impl Field {
    /// The field's raw value in a block's data bytes.
    pub fn read(&self, data: &[u8; 8]) -> u16 {
        match self.width {
            RawType::U8 => u16::from(data[self.at]),
            RawType::U16 => u16::from_le_bytes([data[self.at], data[self.at + 1]]),
            RawType::None => 0,
        }
    }

    /// Stores `raw` at the field (an 8-bit field keeps the low byte).
    pub fn write(&self, data: &mut [u8; 8], raw: u16) {
        match self.width {
            RawType::U8 => data[self.at] = u8::try_from(raw).unwrap_or(u8::MAX),
            RawType::U16 => data[self.at..self.at + 2].copy_from_slice(&raw.to_le_bytes()),
            RawType::None => {}
        }
    }
}

/// Whether and where a written value is kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Storage {
    /// A read or an action: nothing is kept.
    None,
    /// RAM; kept over a power cycle only after WRITE_FLASH.
    Ram,
    /// RAM and never saved (the control mode: every power-up starts in position mode).
    Volatile,
    /// Stored to flash at once (the id).
    Flash,
}

impl Storage {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Ram => "ram",
            Self::Volatile => "volatile",
            Self::Flash => "flash",
        }
    }
}

/// Writes the bus's generic `write_config` must not send, and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Guard {
    None,
    /// Another bus operation sends it (it has effects beyond the device).
    Routed(&'static str),
    /// Not offered at all.
    Dangerous(&'static str),
}

/// One row of the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamRow {
    pub index: u8,
    /// The vendor's name without `CONFIG_` (`BUAD_RATE` as the vendor spells it).
    pub name: &'static str,
    /// snake_case name: the REST field of an `api` row, the simulator's storage key.
    pub key: &'static str,
    pub access: Access,
    pub raw: RawType,
    pub scale: Scale,
    /// Allowed raw values, inclusive.
    pub range: (u16, u16),
    pub reply: ReplyKind,
    /// Where an INFO block shows the value (SPEC §5), if it does.
    pub read_back: Option<Field>,
    pub storage: Storage,
    pub guard: Guard,
    /// Offered by `GET`/`PATCH …/config`.
    pub api: bool,
    /// Factory raw value (what the simulator boots with).
    pub default: u16,
    pub since: Revision,
    pub doc: &'static str,
}

impl ParamRow {
    /// The vendor's full name (`CONFIG_MAX_CUR`).
    pub fn vendor_name(&self) -> String {
        format!("CONFIG_{}", self.name)
    }

    pub fn unit(&self) -> &'static str {
        self.scale.unit()
    }

    pub fn physical(&self, raw: u16) -> f64 {
        self.scale.physical(raw)
    }

    /// Physical → raw within the row's range.
    pub fn to_raw(&self, value: f64) -> Result<u16, UnitError> {
        self.scale.to_raw(self.key, value, self.range)
    }

    /// The physical range (what a REST client may send).
    pub fn physical_range(&self) -> (f64, f64) {
        (self.physical(self.range.0), self.physical(self.range.1))
    }

    /// True if the row stores a value the device keeps in RAM (and in flash after WRITE_FLASH).
    pub fn is_setting(&self) -> bool {
        self.access == Access::Write && self.storage == Storage::Ram
    }

    /// The INFO block a read row asks for.
    pub fn info_block(&self) -> Option<InfoBlock> {
        (self.access == Access::Read)
            .then(|| InfoBlock::from_index(self.index))
            .flatten()
    }
}
