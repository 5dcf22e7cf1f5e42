// The calibration of the joint the panel shows (docs/motion.md): its
// offset, direction (flip) and usable range, read, set whole (PUT) and
// cleared (DELETE). Nothing moves: only how its angles are counted.

import { $, api, act, say, devicePath } from "./api.js";

let shown = null;          // {bus, id} the panel shows
let onChanged = () => {};

export function initCalibration(hooks) {
  onChanged = hooks.onChanged;
  $("#cal-set").onclick = setCalibration;
  $("#cal-clear").onclick = clearCalibration;
}

/** Reads and shows `joint`'s calibration. */
export async function showCalibration(joint) {
  shown = joint;
  $("#cal-state").textContent = "";
  const cal = await act(null, () => api("GET", devicePath(joint, "/calibration")));
  if (cal && shown === joint) fill(cal);
}

function fill(cal) {
  let text = `offset ${cal.offset_deg}°, ${cal.flip ? "flipped" : "not flipped"}`;
  text += cal.range_deg ? `, range ${cal.range_deg[0]}..${cal.range_deg[1]}°` : ", no range (soft limits alone)";
  if (cal.homed_at_ms) text += `; found by homing at ${new Date(cal.homed_at_ms).toLocaleString()}`;
  $("#cal-state").textContent = text;
  $("#cal-offset").value = cal.offset_deg;
  $("#cal-flip").checked = cal.flip;
  $("#cal-low").value = cal.range_deg ? cal.range_deg[0] : "";
  $("#cal-high").value = cal.range_deg ? cal.range_deg[1] : "";
}

/** The form as a request; both range ends or neither (the daemon says what
 *  is wrong with a value). */
function request() {
  const low = $("#cal-low").value, high = $("#cal-high").value;
  const body = { offset_deg: Number($("#cal-offset").value || 0), flip: $("#cal-flip").checked };
  if (low !== "" || high !== "") body.range_deg = [Number(low), Number(high)];
  if ((low === "") !== (high === "")) throw new Error("give both ends of the range, or neither");
  return body;
}

async function setCalibration() {
  const joint = shown;
  const cal = await act(null, () => api("PUT", devicePath(joint, "/calibration"), request()));
  if (!cal) return;
  say(`Calibration of joint ${joint.id} on ${joint.bus} saved.`, "info");
  if (shown === joint) fill(cal);
  onChanged(joint);
}

async function clearCalibration() {
  const joint = shown;
  if (!confirm(`Clear the calibration of joint ${joint.id} on ${joint.bus}? Its angles read as the device's again.`)) return;
  const was = await act(null, () => api("DELETE", devicePath(joint, "/calibration")));
  if (!was) return;
  say(`Calibration of joint ${joint.id} on ${joint.bus} cleared.`, "info");
  onChanged(joint);
}
