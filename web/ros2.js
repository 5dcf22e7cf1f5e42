// The ROS 2 bridge's status (GET /api/v1/ros2, docs/ros2.md), read-only:
// whether this build has it, whether it runs and is connected, and what it
// published, took and refused.

import { $, api, el } from "./api.js";

const REFRESH_MS = 2000;

export function initRos2() {
  refresh();
  setInterval(refresh, REFRESH_MS);
}

const yesNo = (v) => (v ? "yes" : "no");

async function refresh() {
  let s;
  try {
    s = await api("GET", "ros2");
  } catch (e) {
    // Shown where the status is, not as a message every refresh.
    $("#ros2-error").textContent = `Cannot read the ROS 2 bridge's status: ${e.message}`;
    return;
  }
  $("#ros2-error").textContent = "";
  // [label, API field, shown value]
  const rows = [
    ["built", "built", s.built ? "yes" : "no (this build has no ROS 2 bridge)"],
    ["enabled", "enabled", yesNo(s.enabled)],
    ["connected", "connected", yesNo(s.connected)],
    ["sessions opened", "connects", s.connects],
    ["joint states published", "joint_states", s.joint_states],
    ["diagnostics published", "diagnostics", s.diagnostics],
    ["commands applied", "commands_applied", s.commands_applied],
    ["commands refused", "commands_dropped", s.commands_dropped],
    ["latest refusal", "last_dropped", s.last_dropped ?? "–"],
    ["watchdog fired", "watchdog_fired", s.watchdog_fired],
    ["frames lost", "frames_lost", s.frames_lost],
    ["publish errors", "publish_errors", s.publish_errors],
    ["latest error", "last_error", s.last_error ?? "–"],
  ];
  const box = $("#ros2");
  box.classList.toggle("off", !s.enabled);
  box.textContent = "";
  for (const [label, field, value] of rows) {
    box.append(el("span", { textContent: label }), el("span", { textContent: String(value), testid: `ros2-${field}` }));
  }
}
