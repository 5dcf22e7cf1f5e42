//! What the control core refuses, typed: each front-end maps it once (HTTP
//! to a status and problem in `http::error`, the WebSocket to its error
//! codes, ROS 2 to its feedback). The words are the user's: a field, what
//! was wrong with it, the range it must lie in.

use crate::bus::BusError;
use crate::protocol::units::UnitError;
use crate::record::mcap_file::McapFileError;

/// The range a field must lie in.
#[derive(Debug, Clone, PartialEq)]
pub struct Allowed {
    pub min: f64,
    pub max: f64,
    pub unit: String,
}

/// Why a refused value was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InvalidKind {
    /// Not a value the field takes (a malformed combination, a missing part).
    Value,
    /// The same joint or bus named twice in one list.
    Duplicate,
    /// Outside the range the field (or the wire) allows.
    OutOfRange,
    /// Outside the joint's configured soft limits.
    SoftLimit,
    /// Outside the usable range the joint's calibration gives it.
    CalibratedRange,
    /// A grasp's closing limit on the opening side of where a finger is.
    WouldOpen,
}

impl InvalidKind {
    /// The problem type's name (`urn:jointd:problem:<name>`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Value => "invalid-value",
            Self::Duplicate => "duplicate",
            Self::OutOfRange => "out-of-range",
            Self::SoftLimit => "soft-limit",
            Self::CalibratedRange => "calibrated-range",
            Self::WouldOpen => "would-open",
        }
    }

    pub fn title(self) -> &'static str {
        match self {
            Self::Value => "Invalid value",
            Self::Duplicate => "Named twice",
            Self::OutOfRange => "Value out of range",
            Self::SoftLimit => "Target outside the joint's soft limits",
            Self::CalibratedRange => "Target outside the joint's calibrated range",
            Self::WouldOpen => "A grasp that would open a finger",
        }
    }
}

/// A refusal of the control core.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlError {
    /// A request value it will not take.
    #[error("{detail}")]
    Invalid {
        kind: InvalidKind,
        field: String,
        detail: String,
        allowed: Option<Allowed>,
    },
    /// No such bus, device, hand, pose, move or job (`kind` names which).
    #[error("{detail}")]
    NotFound { kind: String, detail: String },
    /// Not in a state to do it now (not enabled, aligning, busy).
    #[error("{detail}")]
    Conflict {
        kind: String,
        title: String,
        detail: String,
        field: Option<String>,
    },
    /// The state file could not be written: nothing was changed.
    #[error("{0}")]
    StateUnwritable(String),
    /// A recording's file could not be made or written; `full`: no room
    /// (disk, quota, file size limit), retrying will not help.
    #[error("{detail}")]
    Storage { full: bool, detail: String },
    /// A finished recording's file could not be read back.
    #[error("{0}")]
    Unreadable(String),
    /// A bug: something the core cannot go on from.
    #[error("internal error: {0}")]
    Internal(String),
    /// The bus could not do it.
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// What control operations return.
pub type ControlResult<T> = Result<T, ControlError>;

impl ControlError {
    pub(crate) fn invalid_as(kind: InvalidKind, field: &str, detail: String) -> Self {
        Self::Invalid {
            kind,
            field: field.to_owned(),
            detail,
            allowed: None,
        }
    }

    fn with_range(mut self, min: f64, max: f64, unit: &str) -> Self {
        if let Self::Invalid { allowed, .. } = &mut self {
            *allowed = Some(Allowed {
                min,
                max,
                unit: unit.to_owned(),
            });
        }
        self
    }

    /// A well-formed value it will not take.
    pub fn invalid(field: &str, detail: impl Into<String>) -> Self {
        Self::invalid_as(InvalidKind::Value, field, detail.into())
    }

    /// The same joint or bus named twice in one list.
    pub fn duplicate(field: &str, detail: impl Into<String>) -> Self {
        Self::invalid_as(InvalidKind::Duplicate, field, detail.into())
    }

    /// A value outside the range its field allows.
    pub fn out_of_range(field: &str, value: f64, (min, max): (f64, f64), unit: &str) -> Self {
        let u = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        Self::invalid_as(
            InvalidKind::OutOfRange,
            field,
            format!("{field} = {value}{u} is out of range; allowed {min}..={max}{u}"),
        )
        .with_range(min, max, unit)
    }

    /// A target outside the joint's configured soft limits.
    pub fn soft_limit(field: &str, value: f64, range: (f64, f64), unit: &str, who: &str) -> Self {
        let (min, max) = range;
        Self::invalid_as(
            InvalidKind::SoftLimit,
            field,
            format!(
                "{field} = {value} {unit} is outside the soft limits of {who} ({min}..={max} {unit})"
            ),
        )
        .with_range(min, max, unit)
    }

    /// A target outside the usable range its calibration gives a joint.
    pub fn calibrated_range(field: &str, value: f64, (min, max): (f64, f64), who: &str) -> Self {
        Self::invalid_as(
            InvalidKind::CalibratedRange,
            field,
            format!(
                "{field} = {value} deg is outside the calibrated range of {who} ({min}..={max} deg)"
            ),
        )
        .with_range(min, max, "deg")
    }

    /// A unit conversion's refusal, said of `field`.
    pub fn from_unit(field: &str, err: UnitError) -> Self {
        match err {
            UnitError::OutOfRange {
                value,
                min,
                max,
                unit,
                ..
            } => Self::out_of_range(field, value, (min, max), unit),
            UnitError::NotFinite { .. } => Self::invalid(field, format!("{field} must be finite")),
            UnitError::NotMultiple { value, step, .. } => Self::invalid(
                field,
                format!("{field} = {value} ms is not a multiple of {step} ms"),
            ),
            UnitError::NotOneOf { .. } => Self::invalid(field, err.to_string()),
        }
    }

    pub fn not_found(kind: &str, detail: impl Into<String>) -> Self {
        Self::NotFound {
            kind: kind.to_owned(),
            detail: detail.into(),
        }
    }

    pub fn unknown_bus(name: &str) -> Self {
        Self::not_found("unknown-bus", format!("no bus named `{name}`"))
    }

    pub fn conflict(kind: &str, title: &str, detail: impl Into<String>) -> Self {
        Self::Conflict {
            kind: kind.to_owned(),
            title: title.to_owned(),
            detail: detail.into(),
            field: None,
        }
    }

    /// The request member a conflict is about.
    pub fn with_field(mut self, name: impl Into<String>) -> Self {
        match &mut self {
            Self::Conflict { field, .. } => *field = Some(name.into()),
            Self::Invalid { field, .. } => *field = name.into(),
            _ => {}
        }
        self
    }

    pub fn state_unwritable(detail: impl Into<String>) -> Self {
        Self::StateUnwritable(detail.into())
    }

    /// A recording whose file could not be created or written.
    pub fn recording_unwritable(err: &McapFileError) -> Self {
        Self::Storage {
            full: err.storage_full(),
            detail: err.to_string(),
        }
    }

    /// A finished recording's file that cannot be read back: not found
    /// when it is no longer on the disk (removed).
    pub fn recording_file_unreadable(
        id: u64,
        path: &std::path::Path,
        err: &std::io::Error,
    ) -> Self {
        if err.kind() == std::io::ErrorKind::NotFound {
            return Self::not_found(
                "recording-file-removed",
                format!(
                    "the file of recording {id} ({}) is no longer on the disk: it was removed",
                    path.display()
                ),
            );
        }
        Self::Unreadable(format!(
            "the file of recording {id} ({}) cannot be read: {err}",
            path.display()
        ))
    }

    pub fn internal(what: impl Into<String>) -> Self {
        Self::Internal(what.into())
    }

    /// Says what was wrong in other words (the kind, field and range stay).
    pub fn with_detail(mut self, words: impl Into<String>) -> Self {
        match &mut self {
            Self::Invalid { detail, .. }
            | Self::NotFound { detail, .. }
            | Self::Conflict { detail, .. }
            | Self::StateUnwritable(detail)
            | Self::Storage { detail, .. }
            | Self::Unreadable(detail)
            | Self::Internal(detail) => *detail = words.into(),
            Self::Bus(_) => {}
        }
        self
    }

    /// The field at fault, when there is one.
    pub fn field(&self) -> Option<&str> {
        match self {
            Self::Invalid { field, .. } => Some(field),
            Self::Conflict { field, .. } => field.as_deref(),
            _ => None,
        }
    }
}
