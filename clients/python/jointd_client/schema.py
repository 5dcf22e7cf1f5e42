"""The daemon's schemas as types (generated from openapi/openapi.json by
clients/python/gen_schema.py: do not edit by hand).

Each object schema is a TypedDict (the answers stay plain dicts at run time);
fields the schema does not require are `total=False` in a second class.
"""

from typing import Any, Dict, List, Literal, Optional, TypedDict, Union


class _ActionDoneRequired(TypedDict):
    action: str
    """`enable`, `disable`, `mode`, `jog`, `rezero`."""
    bus: str


class ActionDone(_ActionDoneRequired, total=False):
    """What a control action did."""

    ids: Optional[List[int]]
    """Devices addressed; absent = every device on the bus."""
    value: Optional[str]
    """Detail of the action, e.g. the mode set or the jog direction."""


class AllowedRange(TypedDict):
    """The allowed range of a field that was out of it."""

    max: float
    min: float
    unit: str


class BaudRequest(TypedDict):
    baud: int
    """One of the device baud levels."""


class BusList(TypedDict):
    buses: List["BusView"]


class BusPatchResult(TypedDict):
    """What a bus-wide PATCH did."""

    bus: str
    devices: List["DevicePatch"]
    """Every device written: its outcome per parameter (written and verified, unverified, not written), by id."""
    method: str
    """`one_frame` (every device runs rev 2.0.8 and every device the bus knows was asked and is online: each parameter went to id 0xFF once, then every device was read back) or `per_device` (one write each: a device runs V2.0.1 or is not known yet, or a skipped device would have heard the frame to 0xFF); `none` for an empty body."""
    offline: List[int]
    """Devices known on the bus but offline: nothing was sent to them."""
    skipped: List["SkippedDevice"]
    """Every device known on the bus and not written, with why."""


class BusReadiness(TypedDict):
    bus: str
    link: str
    """`opening`, `up` or `down`."""


class _BusStopRequired(TypedDict):
    bus: str
    confirmed: List[int]
    """Devices read back afterwards not driving their motor."""
    disabled_again: List[int]
    """Devices read back still driving, which were sent their own disable again (each is then in `confirmed` or `still_enabled`)."""
    frames_sent: int
    """Disable frames written (`0xFF` first, then one per known device)."""
    latency_us: int
    """From the call to the first disable frame handed to the port, µs."""
    preempted_requests: int
    """Queued requests failed because the e-stop went first."""
    still_enabled: List[int]
    """Devices still driving after that second disable: NOT stopped."""
    stopped: bool
    """True when every disable frame was written and no device read back still driving its motor."""
    unconfirmed: List[int]
    """Devices whose state could not be read back (offline or silent): they were sent the disables, but nothing confirms they stopped."""


class BusStop(_BusStopRequired, total=False):
    """What the e-stop did on one bus."""

    error: Optional[str]
    """Why this bus could not be stopped, if it could not."""


class _BusViewRequired(TypedDict):
    adapter: str
    """The USB adapter timing the bus plans for: `native` (a pty, a UART), `ftdi:MS` (MS = its latency timer in effect), `ch340`, `cp2102`, `ft232h:MS`; from the bus's `adapter` setting or sysfs."""
    baud: int
    counters: Dict[str, Any]
    """Monotonic counters since start (frames by kind, CRC errors, timeouts, retries, ...)."""
    devices_known: int
    devices_online: int
    link: str
    """`opening`, `up` or `down`."""
    name: str
    path: str
    polls_in_flight: int
    """Polls written blind behind a USB adapter whose reply is still on its way (0 on a native line)."""
    port_notes: List[str]
    """What opening the port found worth telling (e.g. an FTDI latency timer and its fix)."""
    queue_depth: int
    """One-shot requests waiting for the bus."""
    rates: Dict[str, Any]
    """Rates over the last statistics window (~1 s): frames/s by kind, wire utilisation as the daemon sees it, setpoint age percentiles."""
    transaction_us: int
    """One poll's round trip as the host lives it on that adapter (USB frame wait, both frames, turnaround, the adapter's hold), µs."""


class BusView(_BusViewRequired, total=False):
    """A bus's state and stats."""

    down_reason: Optional[str]
    """Why the bus is down, when it is."""
    retry_in_ms: Optional[int]
    usb_pipeline: Optional["UsbPipelineView"]


class CalibrationRequest(TypedDict, total=False):
    """A calibration to set: it replaces the joint's whole calibration (a field left out takes its default: offset 0, no flip, no range)."""

    flip: Optional[bool]
    offset_deg: Optional[float]
    """The device angle that is to be the joint's zero, degrees (±255)."""
    range_deg: Optional[List[float]]
    """The usable range, joint degrees, `[low, high]`."""


class _CalibrationViewRequired(TypedDict):
    bus: str
    flip: bool
    """The joint counts positive where the device counts negative."""
    id: int
    offset_deg: float
    """The device angle that is the joint's zero, degrees."""


class CalibrationView(_CalibrationViewRequired, total=False):
    """A joint's calibration: `joint = sign · (device − offset_deg)`, sign −1 when `flip`."""

    homed_at_ms: Optional[int]
    """When homing found the offset, Unix ms (`null`: set by hand, or never)."""
    range_deg: Optional[List[float]]
    """The usable range, joint degrees (`null`: the soft limits alone)."""


class CallerView(TypedDict):
    """Who a request is, to the daemon."""

    auth: bool
    """Whether the daemon takes tokens at all (false: everyone may do all)."""
    name: str
    """The token's name (`token` for `--token`; `open` when the daemon takes no token)."""
    scope: str
    """`read`, `operate` or `admin`."""


class ConfigPatch(TypedDict, total=False):
    """Any subset of the writable parameters, in physical units. Written to RAM and verified by read-back; `POST .../config/persist` keeps them over a power cycle."""

    burst_cold_ms: Optional[float]
    """Burst cool-down, 0..=6375 ms, multiples of 25 ms (index 26)."""
    burst_plus_ms: Optional[float]
    """Burst duration, 0..=6375 ms, multiples of 25 ms (index 27)."""
    drv_ot_c: Optional[float]
    """Driver over-temperature threshold (recovers 10 °C below)., 0..=255 °C (index 28). Rev 2.0.8 firmware only (422 for other devices); write-only: no published INFO block shows it, so the write is reported `unverifiable`."""
    lpf_level: Optional[float]
    """Position smoothing level (higher = smoother), 0..=5 (index 16)."""
    max_current_a: Optional[float]
    """Maximum output current, 0..=5.625 A (index 18)."""
    pos_kd: Optional[float]
    """Position loop KD, 0..=7.999755859375 (index 9)."""
    pos_kp: Optional[float]
    """Position loop KP, 0..=7.999755859375 (index 8)."""
    protect_current_limit_a: Optional[float]
    """Current cap while protection is active, 0..=5.625 A (index 19)."""
    protect_current_lv1_a: Optional[float]
    """Protection level-1 threshold, 0..=5.625 A (index 20)."""
    protect_delay_ms: Optional[float]
    """Time above the threshold before protection engages, 0..=65000 ms (index 21)."""
    recover_current_a: Optional[float]
    """Recovery threshold, 0..=5.625 A (index 22)."""
    recover_window_ms: Optional[float]
    """Time below the recovery threshold before protection releases, 0..=65000 ms (index 23)."""
    sn: Optional[float]
    """Serial number (undocumented layout)., 0..=65535 (index 31). Rev 2.0.8 firmware only (422 for other devices); write-only: no published INFO block shows it, so the write is reported `unverifiable`."""
    spd_ki: Optional[float]
    """Speed loop KI, 0..=0.999969482421875 (index 11)."""
    spd_kp: Optional[float]
    """Speed loop KP, 0..=7.999755859375 (index 10)."""
    spd_limit_rpm: Optional[float]
    """Rotor speed limit (Q15); in position mode a zero speed reference moves at it., 0..=50000 rpm (index 30). Rev 2.0.8 firmware only (422 for other devices); write-only: no published INFO block shows it, so the write is reported `unverifiable`."""


class _ConfigViewRequired(TypedDict):
    baud_level: int
    burst_cold_ms: "ParamValue"
    burst_plus_ms: "ParamValue"
    bus: str
    id: int
    lpf_level: "ParamValue"
    max_current_a: "ParamValue"
    param_ver: int
    pos_kd: "ParamValue"
    pos_kp: "ParamValue"
    protect_current_limit_a: "ParamValue"
    protect_current_lv1_a: "ParamValue"
    protect_delay_ms: "ParamValue"
    raw: Dict[str, str]
    """The raw data bytes of each block, hex (INFO_06 carries bytes whose layout is unpublished)."""
    recover_current_a: "ParamValue"
    recover_window_ms: "ParamValue"
    spd_ki: "ParamValue"
    spd_kp: "ParamValue"
    write_only: List[str]
    """Parameters a PATCH may write to this device that no published INFO block shows (rev 2.0.8's `drv_ot_c`, `spd_limit_rpm`, `sn`): written unverifiable, never shown here."""


class ConfigView(_ConfigViewRequired, total=False):
    """Every parameter of a device, read from it now."""

    baud: Optional[int]
    """The device's baud from INFO_04 (absent if its level is unknown); change it on the bus."""
    revision: Optional[str]
    """The protocol revision the device speaks (`2.0.1`, `2.0.8`; absent until known): what this surface offers it."""
    serial_number: Optional[str]
    """INFO_07's data bytes, hex (rev 2.0.8: the serial number, layout unpublished)."""


class _DeviceDetailRequired(TypedDict):
    bus: str
    control_hz: float
    id: int
    limits: "JointLimits"
    """Soft limits that apply to targets of this joint, in its calibrated frame (the config gives them in device degrees)."""
    missed_polls: int
    online: bool
    resets: int
    """Resets (power cuts, reboots) detected since the daemon started."""
    target_known: bool
    """False while the device may hold a target the daemon does not know (not heard from yet, or found enabled at start with the bus's `on_start = "keep"` and sent nothing since): `target` is then `null` meaning *unknown*, not "no target". True otherwise: `target` is the target last put on the wire, or `null` when the joint holds none of the daemon's (disabled, or enabled and holding where it stood)."""
    telemetry_hz: float


class DeviceDetail(_DeviceDetailRequired, total=False):
    """One device's full state."""

    calibration: Optional["CalibrationView"]
    current_limit_owed_a: Optional[float]
    """The current limit a grasp or homing lowered and could not write back yet, A: jointd writes it and reads it back as soon as the joint answers, and refuses every new motion of the joint (409 `current-limit-owed`) until then. `null`: nothing owed."""
    disabled_reason: Optional[str]
    """Why the joint is disabled, when the daemon knows: `reset` (the device lost power or rebooted), `fault`, `estop`, `request` (a disable: REST, WebSocket, the teleop watchdog), `on_start` (found enabled at start, disabled by the bus's `on_start`), `shutdown`. `null` while enabled, or if nothing disabled it since the daemon started."""
    firmware: Optional[str]
    """The firmware version from INFO_01 (`soft_ver`)."""
    last_reset: Optional["ResetView"]
    mode: Optional[str]
    motion: Optional["MotionView"]
    name: Optional[str]
    """The joint's name from the config file (`[[joint]]`), if any."""
    protocol: Optional["RevisionView"]
    status: Optional["StatusView"]
    streamed_by: Optional["Driver"]
    target: Optional["TargetView"]


class DeviceList(TypedDict):
    bus: str
    devices: List["DeviceSummary"]


class _DeviceSummaryRequired(TypedDict):
    control_hz: float
    id: int
    online: bool
    resets: int
    """Resets (power cuts, reboots) detected since the daemon started."""
    target_known: bool
    """False while the device may hold a target the daemon does not know (not heard from yet, or found enabled at start with the bus's `on_start = "keep"` and sent nothing since): `target` is then `null` meaning *unknown*, not "no target". True otherwise: `target` is the target last put on the wire, or `null` when the joint holds none of the daemon's (disabled, or enabled and holding where it stood)."""
    telemetry_hz: float


class DeviceSummary(_DeviceSummaryRequired, total=False):
    """One row of the device list."""

    angle_deg: Optional[float]
    disabled_reason: Optional[str]
    """Why the joint is disabled, when the daemon knows: `reset` (the device lost power or rebooted), `fault`, `estop`, `request` (a disable: REST, WebSocket, the teleop watchdog), `on_start` (found enabled at start, disabled by the bus's `on_start`), `shutdown`. `null` while enabled, or if nothing disabled it since the daemon started."""
    fault: Optional["FaultView"]
    last_reset: Optional["ResetView"]
    mode: Optional[str]
    """Control mode the daemon last set (`position` at power-up)."""
    name: Optional[str]
    """The joint's name from the config file (`[[joint]]`), if any."""
    q_current_a: Optional[float]
    revision: Optional[str]
    """Protocol revision, `2.0.1` or `2.0.8` (absent until known: see the device's `protocol`)."""
    speed_dps: Optional[float]
    """Output-shaft speed, °/s."""
    state: Optional[str]
    """fsm state name from the latest INFO_01."""
    target: Optional["TargetView"]
    telemetry_age_ms: Optional[float]
    """Age of the freshest telemetry block, milliseconds."""
    temp_c: Optional[float]
    vbus_v: Optional[float]


class _DriverRequired(TypedDict):
    client: int
    """The WebSocket connection's number (as in `/metrics`' `client` label); 0 for the ROS 2 bridge."""
    via: "Via"


class Driver(_DriverRequired, total=False):
    """A client that streams setpoints, as the dashboard names it."""

    name: Optional[str]
    """The name the client gave (`?client=` on the WebSocket URL), if any."""


class DroppedCalibrationView(TypedDict):
    bus: str
    id: str
    """The device id as the file has it."""
    reason: str


class EstopResult(TypedDict):
    buses: List["BusStop"]
    elapsed_us: int
    """Wall time of the whole call, µs."""
    stopped: bool


class FaultView(TypedDict):
    """A fault code decoded to names."""

    active: str
    """Name of the active fault (low nibble), `none` when healthy."""
    code: int
    """err_code as sent."""
    history: str
    """Name of the latched fault history (high nibble, rev 2.0.8 firmware)."""


class _FingerGraspRequired(TypedDict):
    bus: str
    close_to_deg: float
    """Where it closes to at most, degrees."""
    contact: bool
    """It touched something (stays true after a loss or a release)."""
    current_limit_restored: bool
    """True only when the current limit read back after the grasp ended shows the previous one (written back, or never changed)."""
    id: int
    joint: str
    """The joint's name in the hand."""
    start_deg: float
    """Where it stood when the grasp began (a plain release opens back to it), degrees."""
    state: "FingerState"


class FingerGrasp(_FingerGraspRequired, total=False):
    """One finger of a grasp job. Angles in the joint's calibrated frame."""

    contact_after_ms: Optional[float]
    """From the grasp's call to contact, ms."""
    contact_deg: Optional[float]
    """Where contact began, degrees."""
    previous_current_limit_a: Optional[float]
    """Its current limit before the grasp, A (INFO_04)."""
    q_current_a: Optional[float]
    """The q current it draws now (smoothed over a few samples), A; the holding current while it holds."""
    reason: Optional[str]
    """Why it failed, stopped or was aborted."""


class FrameLog(TypedDict):
    frames: List["FrameView"]


class FrameView(TypedDict):
    """One frame seen on the wire."""

    at: float
    """Wall-clock time, seconds since the Unix epoch."""
    decoded: Dict[str, Any]
    """The frame decoded (field names as in `jointd frame decode`)."""
    direction: str
    """`tx` (host to devices) or `rx`."""
    hex: str


class GoRequest(TypedDict, total=False):
    """How to go to a pose."""

    duration_ms: Optional[float]
    max_acceleration_dps2: Optional[float]
    max_velocity_dps: Optional[float]
    method: Optional["Method"]


class _GraspJointRequired(TypedDict):
    joint: str
    """The joint's name in the hand."""


class GraspJoint(_GraspJointRequired, total=False):
    """One finger of the hand, by its joint name, and where it closes to."""

    close_to_deg: Optional[float]
    """Where it closes to at most, degrees (calibrated frame); default: the hand's pose `closed`, else the top of the joint's allowed range. Fingers close towards higher angles: a limit below where the finger stands is refused (`would-open`)."""


class _GraspRequestRequired(TypedDict):
    hold_current_a: float
    """The force each finger holds with, as a q current, A (0 < I ≤ 5.625, below the joint's own current limit and its protection level)."""
    speed_dps: float
    """Closing speed at the output, °/s (0 < s ≤ 180, within each finger's soft speed limit, and no slower than the wire carries)."""


class GraspRequest(_GraspRequestRequired, total=False):
    """How to grasp."""

    contact_threshold_a: Optional[float]
    """The rise of q current over what the finger draws moving freely that counts as contact, A (0.02 ≤ t < hold_current_a: below 0.02 the current's noise reads as contact; default 30 % of hold_current_a, at least 0.02)."""
    joints: Optional[List["GraspJoint"]]
    """The fingers (1..=64, each once); default: every joint of the hand."""


class GraspSettings(TypedDict):
    """What the grasp was asked."""

    contact_threshold_a: float
    """The rise of q current over the free-air one that counts as contact, A."""
    hold_current_a: float
    """The current limit each finger holds with, A."""
    speed_dps: float
    """Closing speed at the output, °/s."""


class GraspView(TypedDict):
    """A grasp job as the API reports it."""

    fingers: List["FingerGrasp"]
    hand: str
    id: int
    settings: "GraspSettings"
    state: str
    """`running` while any finger is under the grasp's control; then `done` (each finger's state says how it ended)."""


class _GroupModeRequestRequired(TypedDict):
    mode: "ModeName"


class GroupModeRequest(_GroupModeRequestRequired, total=False):
    ids: Optional[List[int]]


class GroupRequest(TypedDict, total=False):
    """Devices of a group action; no `ids` = every device on the bus."""

    ids: Optional[List[int]]


class _GroupTargetRequired(TypedDict):
    id: int


class GroupTarget(_GroupTargetRequired, total=False):
    """One joint of a group target."""

    position_deg: Optional[float]
    """Output angle, degrees (see `TargetRequest`)."""
    speed_dps: Optional[float]
    """Output-shaft °/s (see `TargetRequest`)."""


class GroupTargetRequest(TypedDict):
    targets: List["GroupTarget"]


class HandCalibration(TypedDict):
    hand: str
    joints: List["JointCalibration"]


class HandJointView(TypedDict):
    bus: str
    id: int
    name: str


class _HandListRequired(TypedDict):
    hands: List["HandView"]


class HandList(_HandListRequired, total=False):
    state_file: Optional["StateFileView"]


class HandView(TypedDict):
    joints: List["HandJointView"]
    name: str
    poses: List[str]
    """The names of its saved poses."""
    streamed_by: List["HandStreamView"]
    """Programs streaming setpoints to its joints now (a WebSocket client such as the LeRobot plugin, or ROS 2 joint commands), oldest first: each with the names of the joints it streams to."""


class Health(TypedDict):
    status: str
    uptime_s: float
    version: str


class HomingJoint(TypedDict, total=False):
    """One joint to home: by `bus` and `id`, or by `hand` and `joint`."""

    bus: Optional[str]
    hand: Optional[str]
    id: Optional[int]
    joint: Optional[str]


class HomingRequest(TypedDict, total=False):
    """What to home and how. Defaults are gentle: 10 °/s under 0.3 A."""

    backoff_deg: Optional[float]
    """How far to move back off the stop, degrees (0..=30; default 2)."""
    current_limit_a: Optional[float]
    """Current limit while searching, A (0 < I, below the joint's own limit; default 0.3)."""
    direction: Optional["Direction"]
    hand: Optional[str]
    """Every joint of this hand."""
    joints: Optional[List["HomingJoint"]]
    """The joints (or give `hand`)."""
    max_travel_deg: Optional[float]
    """The search fails ("no hard stop within ...") after the joint turned this far from where it started, degrees (0 < d ≤ 510; default: the width of the joint's soft range). It also fails at the soft limit in the search direction, whichever comes first."""
    speed_dps: Optional[float]
    """Search speed at the output, °/s (0 < s ≤ 90; default 10)."""
    stop_at_deg: Optional[float]
    """The joint angle the stop reads from then on (default 0). It must lie within the joint's soft range and at least 30° inside the ±255° angle range: 422 with the allowed range otherwise."""
    timeout_ms: Optional[float]
    """Give up the search after this long, ms (0 < t ≤ 120000; default 20000)."""


class HomingView(TypedDict):
    """A homing job as the API reports it."""

    id: int
    joints: List["JointHoming"]
    state: str
    """`running` until every joint ended; then `done` (each joint's state says how)."""


class IdRequest(TypedDict):
    new_id: int
    """1..=159, unused on this bus. Stored to flash by the device at once."""


class IdResult(TypedDict):
    bus: str
    new_id: int
    old_id: int
    verified_by: str


class JogRequest(TypedDict):
    direction: "JogDirection"


class JointCalibration(TypedDict):
    calibration: "CalibrationView"
    joint: str
    """The joint's name in the hand."""


class _JointHomingRequired(TypedDict):
    bus: str
    current_limit_restored: bool
    """True only when the current limit read back after homing shows the previous one (written back, or never changed)."""
    id: int
    phase: str
    """What it does now: `starting`, `searching`, `backing_off`, `restoring`, `done`."""
    state: "HomingState"


class JointHoming(_JointHomingRequired, total=False):
    """One joint of a homing job."""

    hard_stop_device_deg: Optional[float]
    """The device angle where the joint stalled, degrees."""
    offset_deg: Optional[float]
    """The calibration offset recorded from it."""
    previous_current_limit_a: Optional[float]
    """The joint's current limit before homing, A (INFO_04)."""
    reason: Optional[str]
    """Why it failed or was aborted."""


class _JointLimitsRequired(TypedDict):
    max_deg: float
    min_deg: float


class JointLimits(_JointLimitsRequired, total=False):
    """The limits that apply to one joint."""

    max_speed_dps: Optional[float]
    """Output °/s; absent: only the firmware's speed range applies."""


class JointRef(TypedDict):
    """A joint, by bus and id."""

    bus: str
    id: int


class ModeRequest(TypedDict):
    mode: "ModeName"


class MotionView(TypedDict):
    """INFO_02 decoded: fast telemetry."""

    age_ms: float
    angle_deg: float
    d_current_a: float
    q_current_a: float
    raw: str
    rotor_speed_rpm: float
    """Rotor speed before the 568.81:1 gearbox (raw-side; `speed_dps` is the output's)."""
    speed_dps: float
    """Output-shaft speed, °/s."""


class MoveJoint(TypedDict, total=False):
    """One joint and where it goes: by `bus` and `id`, or by `hand` and `joint` (its name in a `[[hand]]` of the config)."""

    bus: Optional[str]
    hand: Optional[str]
    """A hand's name (with `joint`, instead of `bus` and `id`)."""
    id: Optional[int]
    joint: Optional[str]
    """The joint's name in that hand."""
    position_deg: Optional[float]
    """Target, degrees (required unless `waypoints` are given)."""


class _MoveRequestRequired(TypedDict):
    joints: List["MoveJoint"]


class MoveRequest(_MoveRequestRequired, total=False):
    """A move of several joints, which leave together and arrive together."""

    duration_ms: Optional[float]
    """How long the move takes, ms (0 < d ≤ 600000). With velocity or acceleration limits as well, the longer of the two."""
    max_acceleration_dps2: Optional[float]
    """The largest acceleration of any joint, output degrees per second²."""
    max_velocity_dps: Optional[float]
    """The fastest any joint may turn, output degrees per second."""
    method: Optional["Method"]
    waypoints: Optional[List["WaypointRequest"]]
    """Instead of `position_deg`: positions at times (a whole grasp)."""


class _MoveViewRequired(TypedDict):
    arrived: List["JointRef"]
    """Joints that reached the end of the path."""
    duration_ms: float
    id: int
    joints: List["JointRef"]
    method: "Method"
    progress: float
    """Share of its time gone, 0..=1."""
    replaced: List["JointRef"]
    """Joints a newer move or setpoint took over (they left this move)."""
    stalled: List["JointRef"]
    """Joints that could not follow the path (blocked): each holds where it stood."""
    state: "MoveState"
    took_over_from: List[int]
    """Running moves this one took joints from, when it started (each goes on with its other joints)."""


class MoveView(_MoveViewRequired, total=False):
    """A move as the API reports it."""

    reason: Optional[str]
    """Why it was stopped or aborted."""


class NotWritten(TypedDict):
    """A parameter the device does not have: refused, read back with another value, or never sent (an earlier parameter failed, or the bus could not send)."""

    index: int
    param: str
    raw: int
    reason: str
    value: float


class _ParamInfoRequired(TypedDict):
    access: str
    """`read` (asks for an INFO block) or `write`."""
    api: bool
    """Offered by `GET`/`PATCH …/config`."""
    default: float
    default_raw: int
    """Factory value, raw and physical."""
    description: str
    index: int
    key: str
    """The REST field of an `api` row (and the simulator's storage key)."""
    max: float
    min: float
    """Physical range."""
    name: str
    """The vendor's name without `CONFIG_`."""
    raw_max: int
    raw_min: int
    raw_type: str
    """`none`, `u8` or `u16`."""
    reply: str
    """`none`, `res` or `info`."""
    scale: str
    """How raw maps to physical: `plain`, `q12`, `q15_gain`, `q15_current`, `ms`, `x25ms`, `celsius`, `q15_speed`, `id_q7`, `baud_level`, `mode`."""
    since: str
    """Protocol revision that introduced the row."""
    storage: str
    """`ram` (kept after WRITE_FLASH), `flash` (stored at once), `volatile` (never saved), `none`."""
    unit: str


class ParamInfo(_ParamInfoRequired, total=False):
    """One row of the parameter table."""

    guard: Optional[str]
    """Why the generic write path refuses it (routed through another operation, or dangerous)."""
    read_back: Optional["ReadBackInfo"]
    step: Optional[float]
    """Physical values must be multiples of this (absent: rounded to the nearest step)."""


class ParamTable(TypedDict):
    """The parameter table as JSON (`GET /api/v1/params`)."""

    params: List["ParamInfo"]
    """One row per config index of SPEC §4.3 (the INFO reads included), by index."""
    protocol: str
    """The vendor document revision the table is read from; rows carry their own (`since`)."""


class ParamValue(TypedDict):
    """A parameter's value in physical units with the raw value beside it."""

    index: int
    """The config index a write uses."""
    raw: int
    unit: str
    """`A`, `ms`, or empty for gains and levels."""
    value: float


class PatchOutcomes(TypedDict):
    """Every parameter of a PATCH in one of three lists, each in request order: the `partial` member of a PATCH that did not confirm everything."""

    not_written: List["NotWritten"]
    """Not on the device (refused, read back otherwise, or never sent)."""
    unverified: List["Unverified"]
    """Sent, confirmation lost: the device may or may not have them."""
    written: List["Written"]
    """Confirmed on the device (RAM only until persisted)."""


class PatchResult(TypedDict):
    bus: str
    id: int
    written: List["Written"]
    """In request order; RAM only until persisted."""


class PersistResult(TypedDict):
    bus: str
    id: int
    persisted: bool
    verified_by: str


class PoseRequest(TypedDict, total=False):
    """A pose to save: joint angles by joint name, or the hand's current targets."""

    from_current: bool
    """Save where every joint of the hand is now (its last target, else its measured angle) instead."""
    positions_deg: Optional[Dict[str, float]]
    """Degrees by joint name (any subset of the hand's joints, each once)."""


class PoseView(TypedDict):
    hand: str
    name: str
    positions_deg: Dict[str, float]


class _ProblemRequired(TypedDict):
    detail: str
    status: int
    title: str
    type: str
    """A URN naming the kind of problem, e.g. `urn:jointd:problem:device-timeout`."""


class Problem(_ProblemRequired, total=False):
    """RFC 9457 problem details, with jointd's extension members."""

    allowed: Optional["AllowedRange"]
    field: Optional[str]
    """The request field at fault (JSON name), for 400/422."""
    partial: Union["PatchOutcomes", Dict[str, Any]]
    """What was already done before the failure: a config PATCH's per-parameter outcomes (`PatchOutcomes`), or per-bus results of an e-stop or readiness check."""


class ReadBackInfo(TypedDict):
    """A read-back field: which block, where."""

    block: str
    """The vendor name of the read (`INFO_04_R`)."""
    block_index: int
    offset: int
    """Byte offset in the block's 8 data bytes."""
    width: str


class Readiness(TypedDict):
    buses: List["BusReadiness"]
    ready: bool


class RecordingList(TypedDict):
    recordings: List["RecordingView"]


class RecordingRequest(TypedDict, total=False):
    """A recording to start."""

    bag_compatible: Optional[bool]
    """Write frames, events and setpoints as `std_msgs/msg/String` (CDR, the same JSON text) instead of JSON, so every channel has one ROS serialization, as `ros2 bag play` asks (default false)."""
    buses: Optional[List[str]]
    """The buses to record (default: all)."""
    duration_s: Optional[float]
    """Stop by itself after this long, s (0 < d ≤ 86400); absent: until `DELETE`."""


class _RecordingViewRequired(TypedDict):
    buses: List[str]
    file: str
    """The file's name in the daemon's recordings directory."""
    id: int
    lost: int
    """Frames or targets the recording fell too far behind to keep."""
    messages: Dict[str, int]
    """Messages written, by topic."""
    started_ms: int
    """Unix ms it started and ended."""
    state: str
    """`recording`, `finished` (the file is complete) or `failed`."""


class RecordingView(_RecordingViewRequired, total=False):
    """A recording as the API reports it."""

    duration_s: Optional[float]
    ended_ms: Optional[int]
    error: Optional[str]


class ReleaseRequest(TypedDict, total=False):
    """How to let go."""

    open_deg: Optional[float]
    """Open each finger by this much from where it is, degrees (0 < d ≤ 180)."""
    pose: Optional[str]
    """Open to this pose of the hand (its angle for each finger)."""
    speed_dps: Optional[float]
    """Opening speed, °/s (default: the closing speed), checked as the closing speed is."""


class ResetView(TypedDict):
    """A reset (power cut, reboot) the daemon detected."""

    age_ms: float
    """Milliseconds since it was detected."""
    seen: str
    """What showed it: `announcement` (its unsolicited power-up INFO_01) or `state_dropped` (ready again while the daemon believed it enabled)."""
    state: str
    state_before: str
    """State before (`unknown` if never read) and in the reply that showed it."""


class _RevisionViewRequired(TypedDict):
    revision: str
    """`2.0.1` or `2.0.8`: what the config surface offers and how state codes read."""
    source: str
    """`config` (the bus's `firmware` setting) or `detected` (the device answered an INFO_07 read: 2.0.8; or stayed silent to it: 2.0.1)."""


class RevisionView(_RevisionViewRequired, total=False):
    """The protocol revision a device speaks, and how the daemon knows."""

    serial_number: Optional[str]
    """INFO_07's 8 data bytes, hex: the serial number (rev 2.0.8; the layout is unpublished, so the bytes are given as they came)."""


class _Ros2ViewRequired(TypedDict):
    built: bool
    """This build has the bridge (cargo feature `ros2`)."""
    commands_applied: int
    """`joint_commands` applied."""
    commands_dropped: int
    """`joint_commands` refused whole (unknown joint, out of limits, NaN, not enabled)."""
    connected: bool
    """A Zenoh session is open and, in client mode, its router reachable. The bridge retries in the background (0.5 s doubling to 30 s) while it is not; the daemon serves regardless."""
    connects: int
    """Sessions opened since start (a reconnection counts again)."""
    diagnostics: int
    """`DiagnosticArray` messages published."""
    enabled: bool
    """The bridge runs (`--ros2` or `[ros2] enabled`)."""
    frames_lost: int
    """Frames the bridge fell too far behind to see."""
    joint_states: int
    """`JointState` messages published (all buses)."""
    publish_errors: int
    watchdog_fired: int
    """Times the command stream stopped and `[watchdog]` acted."""


class Ros2View(_Ros2ViewRequired, total=False):
    """The ROS 2 bridge's counters."""

    last_dropped: Optional[str]
    """Why the latest one was refused."""
    last_error: Optional[str]
    """Why the latest attempt to connect failed, or the latest session was lost."""


class ScanRequest(TypedDict):
    """An id range to scan, inclusive."""

    first: int
    last: int


class ScanResult(TypedDict):
    bus: str
    found: List[int]
    """Ids that answered INFO_01."""


class SetAsideView(TypedDict):
    moved_to: str
    reason: str


class SkippedDevice(TypedDict):
    """A device a bus-wide PATCH left out."""

    id: int
    reason: str
    """`offline` (it does not answer: a write could not be verified), or `unmanaged` (not one of the bus's configured `ids`; ask with `include_unmanaged=true`)."""


class _StateFileViewRequired(TypedDict):
    dropped_calibrations: List["DroppedCalibrationView"]
    """Calibrations of the file that could not be applied, dropped (those joints read uncalibrated); the rest of the file was kept."""
    path: str


class StateFileView(_StateFileViewRequired, total=False):
    """The state file, and what was wrong with it when the daemon started."""

    set_aside: Optional["SetAsideView"]
    unusable: Optional[str]
    """The file could neither be used nor set aside: it is left as it is and saving answers 503. `null`: saving works."""


class StatusView(TypedDict):
    """INFO_01 decoded: state and health."""

    age_ms: float
    """Milliseconds since this block was received."""
    angle_deg: float
    fault: "FaultView"
    firmware: str
    raw: str
    """The 8 data bytes as received, hex."""
    soft_ver: int
    state: str
    """`ready`, `align`, `run`, `fault`, ..."""
    state_code: int
    """The fsm code as sent (raw; `state` names it)."""
    temp_c: float
    vbus_v: float


class TargetAck(TypedDict):
    """What a target request did."""

    bus: str
    on_wire: bool
    """True when the frame carrying the targets has been written to the port (status 200); false when still waiting (status 202)."""
    seq: int
    """Sequence number of this write in the bus's setpoint store."""
    targets: List["JointTarget"]


class TargetRequest(TypedDict, total=False):
    """A target for one joint. Position mode: `position_deg` (required) and `speed_dps` as the speed limit (default 30 °/s, capped by the soft limit). Speed mode: `speed_dps` (signed, required) only."""

    position_deg: Optional[float]
    """Output angle, degrees (−255..=255, narrowed by soft limits)."""
    speed_dps: Optional[float]
    """Output-shaft °/s: the speed limit in position mode (≥ 0), the speed in speed mode (signed); within the firmware's base speed (50000 rotor rpm, 527 °/s, from 1.2.4; else 40000 rpm, 422 °/s)."""


class TargetView(TypedDict):
    """A target in physical units (the joint's calibrated frame) with its raw wire values (the device's)."""

    pos_ref_raw: int
    position_deg: float
    spd_ref_raw: int
    speed_dps: float
    """Output-shaft °/s: the speed limit in position mode, the speed in speed mode."""


class Unverified(TypedDict):
    """A parameter sent whose confirmation (read-back or RES) was lost after the retries: the device may or may not have the value."""

    index: int
    param: str
    raw: int
    reason: str
    value: float


class UsbPipelineView(TypedDict):
    """What the bus view shows of the pipeline."""

    arrival_lag_us: int
    """How late the bus thread wakes (a high quantile, measured on its timed waits), µs: the frame clock learnt from reply arrivals may run this much behind the adapter's, and each write spares it before its boundary."""
    backoffs: int
    """Steps up and down since start."""
    confirming: bool
    """Writes are confirmed: the port says when the adapter took each, and the wire is held as it says, not for a write's reach."""
    counts_given_up: int
    """Confirmed writes whose output count stayed up for 4 ms after their USB frame (evidence: the count is not trusted)."""
    guard_us: int
    """How late a write may reach the adapter and still leave where the wire is held for it, µs."""
    incidents_per_s: float
    """Incidents (evidence of a collision) per second over the last 10 s."""
    late_writes: int
    """Writes seen to reach the adapter a frame late while backed off (harmless then; each restarts the clean time)."""
    lead_us: int
    """How far before its USB frame boundary a write is aimed, µs."""
    mode: "PipelineMode"
    reason: str
    """Why the mode last changed (`start` until it has)."""
    recover_after_ms: int
    """How long the mode must stay clean before stepping down, ms."""
    recoveries: int
    sentinels: int
    """Sentinel transfers (written a tenth of a frame before their boundary, the wire held a frame longer) whose reply was matched, and those of them that reached the adapter a frame late."""
    sentinels_late: int
    since_s: float
    """Seconds since that change."""
    writes_taken_late: int
    """Confirmed writes seen taken half a frame or more after the boundary they were aimed at (each held the wire that much longer, no collision): late writes, and looks the owner made late."""


class WaypointRequest(TypedDict):
    """A waypoint: every joint's position, reached at `at_ms` after the start."""

    at_ms: float
    positions_deg: List[float]
    """One position per joint, in the order of `joints`, degrees."""


class Written(TypedDict):
    """One verified write."""

    index: int
    param: str
    raw: int
    value: float
    verified_by: str
    """`res` (the device's RES reply) or `read_back` (the INFO block read back)."""


DevicePatch = Dict[str, Any]
Direction = Literal["negative", "positive"]
FingerState = Literal["starting", "closing", "holding", "no_contact", "lost", "releasing", "released", "stopped", "aborted", "failed"]
HandStreamView = Dict[str, Any]
HomingState = Literal["running", "homed", "failed", "aborted"]
JogDirection = Literal["cw", "ccw"]
JointTarget = Dict[str, Any]
McapBytes = str
Method = Literal["linear", "min_jerk", "trapezoid"]
ModeName = Literal["position", "speed", "current"]
MoveState = Literal["running", "done", "stopped", "aborted", "stalled"]
PipelineMode = Literal["pipelined", "guarded", "lockstep"]
Via = Literal["websocket", "ros2"]
__all__ = [
    "ActionDone",
    "AllowedRange",
    "BaudRequest",
    "BusList",
    "BusPatchResult",
    "BusReadiness",
    "BusStop",
    "BusView",
    "CalibrationRequest",
    "CalibrationView",
    "CallerView",
    "ConfigPatch",
    "ConfigView",
    "DeviceDetail",
    "DeviceList",
    "DevicePatch",
    "DeviceSummary",
    "Direction",
    "Driver",
    "DroppedCalibrationView",
    "EstopResult",
    "FaultView",
    "FingerGrasp",
    "FingerState",
    "FrameLog",
    "FrameView",
    "GoRequest",
    "GraspJoint",
    "GraspRequest",
    "GraspSettings",
    "GraspView",
    "GroupModeRequest",
    "GroupRequest",
    "GroupTarget",
    "GroupTargetRequest",
    "HandCalibration",
    "HandJointView",
    "HandList",
    "HandStreamView",
    "HandView",
    "Health",
    "HomingJoint",
    "HomingRequest",
    "HomingState",
    "HomingView",
    "IdRequest",
    "IdResult",
    "JogDirection",
    "JogRequest",
    "JointCalibration",
    "JointHoming",
    "JointLimits",
    "JointRef",
    "JointTarget",
    "McapBytes",
    "Method",
    "ModeName",
    "ModeRequest",
    "MotionView",
    "MoveJoint",
    "MoveRequest",
    "MoveState",
    "MoveView",
    "NotWritten",
    "ParamInfo",
    "ParamTable",
    "ParamValue",
    "PatchOutcomes",
    "PatchResult",
    "PersistResult",
    "PipelineMode",
    "PoseRequest",
    "PoseView",
    "Problem",
    "ReadBackInfo",
    "Readiness",
    "RecordingList",
    "RecordingRequest",
    "RecordingView",
    "ReleaseRequest",
    "ResetView",
    "RevisionView",
    "Ros2View",
    "ScanRequest",
    "ScanResult",
    "SetAsideView",
    "SkippedDevice",
    "StateFileView",
    "StatusView",
    "TargetAck",
    "TargetRequest",
    "TargetView",
    "Unverified",
    "UsbPipelineView",
    "Via",
    "WaypointRequest",
    "Written",
]
