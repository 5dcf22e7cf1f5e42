//! The enumerated values that frames and parameters carry: which INFO block
//! a read asks for, the control mode (index 7), the baud level (index 15).
//! Apart from the codec and the parameter table so that both can name them
//! without importing each other.

/// The INFO blocks a read asks for, by the index of the read command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum InfoBlock {
    Info01 = 1,
    Info02 = 2,
    Info03 = 12,
    Info04 = 17,
    Info05 = 24,
    Info06 = 25,
    /// Serial number bytes (rev 2.0.8).
    Info07 = 32,
}

impl InfoBlock {
    pub const ALL: [InfoBlock; 7] = [
        Self::Info01,
        Self::Info02,
        Self::Info03,
        Self::Info04,
        Self::Info05,
        Self::Info06,
        Self::Info07,
    ];

    pub fn index(self) -> u8 {
        self as u8
    }

    pub fn from_index(index: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|b| b.index() == index)
    }
}

/// Control mode (index 7). Not saved: every power-up starts in position mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum CtrlMode {
    None = 0,
    Speed = 1,
    Position = 2,
    /// rev 2.0.8 only.
    Current = 3,
}

impl CtrlMode {
    pub const ALL: [CtrlMode; 4] = [Self::None, Self::Speed, Self::Position, Self::Current];

    pub fn from_raw(raw: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|m| *m as u8 == raw)
    }

    /// The name every interface uses (`"position"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Speed => "speed",
            Self::Position => "position",
            Self::Current => "current",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

impl std::fmt::Display for CtrlMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Baud levels of index 15 (SPEC §1; errata 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum BaudLevel {
    B500000 = 0,
    B230400 = 1,
    B115200 = 2,
    B38400 = 3,
    B19200 = 4,
}

impl BaudLevel {
    pub const ALL: [BaudLevel; 5] = [
        Self::B500000,
        Self::B230400,
        Self::B115200,
        Self::B38400,
        Self::B19200,
    ];

    pub fn baud(self) -> u32 {
        match self {
            Self::B500000 => 500_000,
            Self::B230400 => 230_400,
            Self::B115200 => 115_200,
            Self::B38400 => 38_400,
            Self::B19200 => 19_200,
        }
    }

    pub fn from_raw(raw: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|l| *l as u8 == raw)
    }

    pub fn from_baud(baud: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|l| l.baud() == baud)
    }
}
