// Homing the joint the panel shows (POST /api/v1/homing, docs/motion.md):
// it turns slowly under a reduced current limit until it finds its hard
// stop, which becomes its calibration offset. The daemon refuses a joint
// the user has not enabled (409, shown); the state is followed until done.

import { $, api, act, say, watch } from "./api.js";

let shown = null;          // {bus, id} the panel shows
let job = null;            // the homing job followed for it
let onHomed = () => {};

export function initHoming(hooks) {
  onHomed = hooks.onHomed;
  $("#home").onclick = startHoming;
}

/** The panel now shows `joint`: another joint's job is no longer shown. */
export function showHomingFor(joint) {
  shown = joint;
  job = null;
  $("#home-state").textContent = "";
  delete $("#home-state").dataset.state;
}

function request() {
  const num = (sel) => ($(sel).value === "" ? undefined : Number($(sel).value));
  return {
    joints: [{ bus: shown.bus, id: shown.id }],
    direction: $("#home-direction").value,
    speed_dps: num("#home-speed"),
    current_limit_a: num("#home-current"),
    stop_at_deg: num("#home-stop-at"),
  };
}

async function startHoming() {
  const joint = shown;
  const started = await act(null, () => api("POST", "homing", request()));
  if (!started || shown !== joint) return;
  say(`Homing ${started.id} of joint ${joint.id} on ${joint.bus} started.`, "info");
  job = started.id;
  show(started);
  const end = await watch(`homing/${started.id}`, show, (v) => v.state !== "running" || job !== started.id, 250);
  if (!end || end.state === "running") return;
  const j = end.joints[0];
  if (j.state !== "homed") say(`Homing ${end.id} of joint ${joint.id}: ${j.state}${j.reason ? ` — ${j.reason}` : ""}.`);
  onHomed(joint);
}

/** `Homing 3: done — homed at device -40.0°, offset -40.0°; current limit restored`. */
function show(v) {
  if (v.id !== job) return;
  const j = v.joints[0];
  let text = `Homing ${v.id}: ${v.state} — ${j.state}`;
  if (j.state === "running") text += ` (${j.phase})`;
  if (j.hard_stop_device_deg !== null && j.hard_stop_device_deg !== undefined) text += ` at device ${j.hard_stop_device_deg.toFixed(1)}°`;
  if (j.offset_deg !== null && j.offset_deg !== undefined) text += `, offset ${j.offset_deg.toFixed(1)}°`;
  if (j.reason) text += `: ${j.reason}`;
  if (v.state !== "running") text += j.current_limit_restored ? "; current limit restored" : "; current limit NOT confirmed restored";
  $("#home-state").textContent = text;
  $("#home-state").dataset.state = v.state === "running" ? "running" : j.state;
}
