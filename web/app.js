// jointd dashboard: REST for commands and configuration, the WebSocket
// (jointd.ws.v1, docs/websocket.md) for live telemetry. No build step: ES
// modules, one job each (api.js talks to the daemon; moves, homing,
// calibration, hands, recordings and ros2 each own their part of the page).
// This one owns the telemetry, the device table, the joint panel's target,
// configuration and frames, and the e-stop.

import { $, API, session, say, api, act, whenUnauthorized, devicePath } from "./api.js";
import { initMoves, showMovesFor, startMove } from "./moves.js";
import { initHoming, showHomingFor } from "./homing.js";
import { initCalibration, showCalibration } from "./calibration.js";
import { initHands } from "./hands.js";
import { initRecordings } from "./recordings.js";
import { initRos2 } from "./ros2.js";
import { initDoctor } from "./doctor.js";
import { loadScope } from "./scope.js";

const TELEMETRY_HZ = 20;
const PLOT_SECONDS = 10;

const state = {
  joints: new Map(),          // "bus/id" -> latest telemetry joint
  history: new Map(),         // "bus/id" -> [{t, angle, target, current}]
  busHistory: new Map(),      // bus -> [{t, occupancy, fps}]
  lastCounters: new Map(),    // bus -> {t, counters}
  selected: null,             // {bus, id}
  ws: null,
  config: null,
  configFor: null,            // {bus, id} the parameter table was read from
};

// ---------------------------------------------------------------- token

function askToken() {
  $("#token-button").hidden = false;
  const dlg = $("#token-dialog");
  if (!dlg.open) dlg.showModal();
}
whenUnauthorized(askToken);

$("#token-dialog").addEventListener("close", () => {
  session.token = $("#token-input").value.trim();
  localStorage.setItem("jointd-token", session.token);
  connect();
  refreshBuses();
  loadScope();
});
$("#token-button").onclick = askToken;

// ---------------------------------------------------------------- WebSocket telemetry

function connect() {
  if (state.ws) state.ws.close();
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const q = session.token ? `?token=${encodeURIComponent(session.token)}` : "";
  const ws = new WebSocket(`${proto}://${location.host}${API}/ws${q}`);
  state.ws = ws;
  ws.onopen = () => {
    setLink(true);
    ws.send(JSON.stringify({ type: "subscribe", seq: 1, rate_hz: TELEMETRY_HZ }));
  };
  ws.onclose = () => {
    setLink(false);
    if (state.ws === ws) setTimeout(connect, 1000);
  };
  ws.onmessage = (ev) => onMessage(JSON.parse(ev.data));
}

function setLink(up) {
  $("#link").className = up ? "dot up" : "dot down";
  $("#link").textContent = up ? "live" : "reconnecting…";
}

function onMessage(msg) {
  if (msg.type === "telemetry") {
    const now = performance.now() / 1000;
    for (const j of msg.joints) {
      const key = `${j.bus}/${j.id}`;
      state.joints.set(key, j);
      const h = state.history.get(key) || [];
      h.push({ t: now, angle: j.angle_deg, target: j.target_deg, current: j.q_current_a });
      while (h.length && h[0].t < now - PLOT_SECONDS) h.shift();
      state.history.set(key, h);
    }
    renderDevices();
    renderPlot();
  } else if (msg.type === "event") {
    const e = msg.event;
    if (e.event === "fault") say(`Joint ${e.id} on ${e.bus}: fault ${e.name}`);
    else if (e.event === "bus_down") say(`Bus ${e.bus} is down: ${e.reason}`);
    else if (e.event === "watchdog") say(`Teleop watchdog (${e.why}): ${e.policy} on ${e.joints.length} joints`);
    else if (e.event === "estop") say(`Emergency stop on ${e.bus}`, "info");
  } else if (msg.type === "error") {
    say(`WebSocket: ${msg.message}`);
  }
}

// ---------------------------------------------------------------- device table

const fmt = (v, digits = 1) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));

function renderDevices() {
  const tbody = $("#devices tbody");
  const keys = [...state.joints.keys()].sort((a, b) => {
    const [ba, ia] = a.split("/"); const [bb, ib] = b.split("/");
    return ba === bb ? ia - ib : ba.localeCompare(bb);
  });
  for (const key of keys) {
    const j = state.joints.get(key);
    let tr = tbody.querySelector(`tr[data-key="${key}"]`);
    if (!tr) {
      tr = document.createElement("tr");
      tr.dataset.key = key;
      tr.dataset.testid = `device-row-${j.bus}-${j.id}`;
      tr.setAttribute("data-testid", `device-row-${j.bus}-${j.id}`);
      tr.innerHTML = "<td></td>".repeat(12);
      tr.onclick = () => select(j.bus, j.id);
      tbody.appendChild(tr);
    }
    const cells = [j.bus, j.id, j.name ?? "", j.state ?? "–", j.fault ?? "–", fmt(j.angle_deg, 2), fmt(j.target_deg, 2),
      fmt(j.speed_dps, 1), fmt(j.q_current_a, 3), fmt(j.vbus_v, 2), fmt(j.temp_c, 0), fmt(j.age_ms, 0)];
    const fields = ["bus", "id", "name", "state", "fault", "angle_deg", "target_deg", "speed_dps", "q_current_a", "vbus_v", "temp_c", "age_ms"];
    cells.forEach((c, i) => {
      const td = tr.children[i];
      td.dataset.field = fields[i];
      if (td.textContent !== String(c)) td.textContent = c;
    });
    tr.children[4].className = j.fault && j.fault !== "none" ? "fault" : "";
    tr.classList.toggle("offline", !j.online);
    tr.classList.toggle("selected", state.selected && key === `${state.selected.bus}/${state.selected.id}`);
  }
}

// ---------------------------------------------------------------- bus overview

async function refreshBuses() {
  let data;
  try { data = await api("GET", "buses"); } catch (e) { return; }
  const now = performance.now() / 1000;
  const root = $("#buses");
  for (const b of data.buses) {
    const prev = state.lastCounters.get(b.name);
    state.lastCounters.set(b.name, { t: now, c: b.counters });
    let occupancy = null, fps = null, rx = null;
    if (prev) {
      const dt = now - prev.t;
      const tx = (c) => (c.frames_tx_broadcast || 0) + (c.frames_tx_control || 0) + (c.frames_tx_config || 0) + (c.frames_tx_jog || 0);
      fps = (tx(b.counters) - tx(prev.c)) / dt;
      rx = ((b.counters.frames_rx || 0) - (prev.c.frames_rx || 0)) / dt;
      occupancy = ((b.counters.wire_busy_us || 0) - (prev.c.wire_busy_us || 0)) / 1e6 / dt;
    }
    const h = state.busHistory.get(b.name) || [];
    if (occupancy !== null) h.push({ t: now, occupancy, fps });
    while (h.length && h[0].t < now - 60) h.shift();
    state.busHistory.set(b.name, h);
    let card = root.querySelector(`[data-bus="${b.name}"]`);
    if (!card) {
      card = document.createElement("div");
      card.className = "bus";
      card.dataset.bus = b.name;
      card.innerHTML = `<b></b><div class="kv"></div><canvas width="400" height="70"></canvas>`;
      root.appendChild(card);
    }
    card.querySelector("b").textContent = `${b.name} — ${b.path}`;
    const c = b.counters;
    const kv = {
      link: b.link + (b.down_reason ? ` (${b.down_reason})` : ""), baud: b.baud,
      devices: `${b.devices_online} online / ${b.devices_known} known`,
      occupancy: occupancy === null ? "–" : `${(occupancy * 100).toFixed(1)} %`,
      "tx frames/s": fps === null ? "–" : fps.toFixed(0), "rx frames/s": rx === null ? "–" : rx.toFixed(0),
      "CRC errors": c.crc_errors ?? 0, timeouts: c.timeouts ?? 0, retries: c.retries ?? 0, "queue depth": b.queue_depth,
    };
    card.querySelector(".kv").innerHTML = Object.entries(kv).map(([k, v]) => `<span>${k}</span><span data-field="${k}">${v}</span>`).join("");
    drawSeries(card.querySelector("canvas"), h, [{ key: "occupancy", color: "#1d4ed8", max: 1 }]);
  }
}

// ---------------------------------------------------------------- plots

function drawSeries(canvas, points, series, t0, t1) {
  const ctx = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height;
  ctx.clearRect(0, 0, w, h);
  if (points.length < 2) return;
  const start = t0 ?? points[0].t, end = t1 ?? points[points.length - 1].t;
  const x = (t) => ((t - start) / Math.max(end - start, 1e-6)) * (w - 40) + 35;
  ctx.strokeStyle = "#e5e7eb"; ctx.beginPath(); ctx.moveTo(35, h - 15); ctx.lineTo(w - 5, h - 15); ctx.stroke();
  for (const s of series) {
    const vals = points.map((p) => p[s.key]).filter((v) => v !== null && v !== undefined);
    if (!vals.length) continue;
    const lo = s.min ?? Math.min(...vals, 0), hi = s.max ?? Math.max(...vals, lo + 1);
    const y = (v) => h - 15 - ((v - lo) / Math.max(hi - lo, 1e-9)) * (h - 25);
    ctx.strokeStyle = s.color; ctx.lineWidth = 1.5; ctx.beginPath();
    let started = false;
    for (const p of points) {
      const v = p[s.key];
      if (v === null || v === undefined) continue;
      if (!started) { ctx.moveTo(x(p.t), y(v)); started = true; } else ctx.lineTo(x(p.t), y(v));
    }
    ctx.stroke();
    if (s.label !== false) {
      ctx.fillStyle = s.color; ctx.font = "11px sans-serif";
      ctx.fillText(`${fmt(hi, 1)}`, s.right ? w - 38 : 2, 12);
      ctx.fillText(`${fmt(lo, 1)}`, s.right ? w - 38 : 2, h - 18);
    }
  }
}

function renderPlot() {
  if (!state.selected) return;
  const key = `${state.selected.bus}/${state.selected.id}`;
  const h = state.history.get(key) || [];
  const now = performance.now() / 1000;
  const angles = h.flatMap((p) => [p.angle, p.target]).filter((v) => v !== null && v !== undefined);
  const lo = Math.min(...angles, -1), hi = Math.max(...angles, 1);
  drawSeries($("#plot"), h, [
    { key: "target", color: "#9ca3af", min: lo, max: hi, label: false },
    { key: "angle", color: "#1d4ed8", min: lo, max: hi },
    { key: "current", color: "#d97706", right: true },
  ], now - PLOT_SECONDS, now);
}

// ---------------------------------------------------------------- device panel

function dev(path = "") {
  return devicePath(state.selected, path);
}

/** True when `a` and `b` name the same joint. */
const sameJoint = (a, b) => !!a && !!b && a.bus === b.bus && a.id === b.id;

async function select(bus, id) {
  state.selected = { bus, id };
  // The parameter table belongs to the joint it was read from: cleared at
  // once, so nothing shown (or edited) for the last joint is applied to this one.
  clearConfig();
  $("#panel").hidden = false;
  $("#panel-title").textContent = `${id} on ${bus}`;
  showPartsFor({ bus, id });
  renderDevices();
  const detail = await act(null, () => api("GET", dev()));
  // Another joint was clicked meanwhile: its own select() fills the panel.
  if (!sameJoint({ bus, id }, state.selected)) return;
  if (detail) {
    const lim = detail.limits || {};
    const slider = $("#target-slider");
    slider.min = lim.min_deg ?? -255; slider.max = lim.max_deg ?? 255;
    const target = detail.target ? detail.target.position_deg : (detail.motion ? detail.motion.angle_deg : 0);
    slider.value = target; $("#target-number").value = target;
    if (detail.mode) $("#mode").value = detail.mode;
    if (detail.name) $("#panel-title").textContent = `${id} (${detail.name}) on ${bus}`;
    showFirmware(detail);
  }
  loadConfig();
  loadFrames();
}

/** The panel's parts that other modules own, told which joint it shows. */
function showPartsFor(joint) {
  showMovesFor(joint);
  showHomingFor(joint);
  showCalibration(joint);
}

/** Firmware version, protocol revision (and how the daemon knows), serial;
 *  current mode is offered to rev 2.0.8 devices only. */
function showFirmware(detail) {
  const p = detail.protocol;
  const parts = [];
  if (detail.firmware) parts.push(`firmware ${detail.firmware}`);
  parts.push(p ? `protocol rev ${p.revision} (${p.source})` : "protocol revision not known yet");
  if (p && p.serial_number) parts.push(`serial ${p.serial_number}`);
  $("#panel-firmware").textContent = parts.join(" · ");
  $('#mode option[value="current"]').disabled = !(p && p.revision === "2.0.8");
}

function sendTarget(deg) {
  const speed = Number($("#speed-limit").value) || undefined;
  return act(null, () => api("PUT", dev("/target"), { position_deg: deg, speed_dps: speed }));
}

$("#enable").onclick = () => act("Enabled (the first enable aligns for about a second).", () => api("POST", dev("/enable")));
$("#disable").onclick = () => act("Disabled.", () => api("POST", dev("/disable")));
$("#jog-cw").onclick = () => act("Jogged +5°.", () => api("POST", dev("/jog"), { direction: "cw" }));
$("#jog-ccw").onclick = () => act("Jogged −3°.", () => api("POST", dev("/jog"), { direction: "ccw" }));
$("#rezero").onclick = () => act("Re-zeroed.", () => api("POST", dev("/rezero")));
$("#mode").onchange = (e) => act(`Mode set to ${e.target.value}.`, () => api("PUT", dev("/mode"), { mode: e.target.value }));

/** With a duration, a smooth move the daemon generates (moves.js); without
 *  one, a plain target at the speed limit. */
$("#move").onclick = () => {
  const deg = Number($("#target-number").value);
  const ms = Number($("#move-ms").value);
  if (!(ms > 0)) return sendTarget(deg);
  return startMove(state.selected, deg, ms, $("#move-method").value);
};
$("#target-number").onchange = (e) => { $("#target-slider").value = e.target.value; };

// The slider streams targets while it moves, at most every 50 ms.
let sliderTimer = null;
$("#target-slider").oninput = (e) => {
  $("#target-number").value = e.target.value;
  if (sliderTimer) return;
  sliderTimer = setTimeout(() => { sliderTimer = null; sendTarget(Number($("#target-slider").value)); }, 50);
};
$("#target-slider").onchange = (e) => sendTarget(Number(e.target.value));

// ---------------------------------------------------------------- configuration

// Which parameters exist, their labels, units and ranges come from the
// daemon's parameter table (GET /api/v1/params), not from a copy here.
let paramTable = null;

/** The rows the configuration form offers, in table order (fetched once). */
async function offeredParams() {
  if (!paramTable) {
    const table = await api("GET", "params");
    paramTable = table.params.filter((p) => p.api);
  }
  return paramTable;
}

/** A parameter as a person reads it: at most 4 decimals, no float noise. */
const shown = (v) => String(Number(Number(v).toFixed(4)));

function clearConfig() {
  state.config = null;
  state.configFor = null;
  $("#config tbody").innerHTML = "";
}

async function loadConfig() {
  const joint = { ...state.selected };
  const rows = await act(null, offeredParams);
  const cfg = rows && await act(null, () => api("GET", dev("/config")));
  // Another joint was selected meanwhile: this answer is not its table.
  if (!cfg || !sameJoint(joint, state.selected)) return;
  state.config = cfg;
  state.configFor = joint;
  const tbody = $("#config tbody");
  tbody.innerHTML = "";
  for (const row of rows) {
    const name = row.key;
    const p = cfg[name];
    if (!p) continue;
    const tr = document.createElement("tr");
    tr.innerHTML = `<td></td><td><input data-param="${name}" data-testid="param-${name}" type="number"></td><td></td><td>${p.raw}</td>`;
    tr.children[0].textContent = row.description;
    tr.children[0].title = `${row.name} (index ${row.index}), ${shown(row.min)}..${shown(row.max)} ${row.unit}`;
    tr.children[2].textContent = p.unit;
    const input = tr.querySelector("input");
    input.min = row.min; input.max = row.max; input.step = row.step ?? "any";
    // Shown rounded (Q12/Q15 steps print as 0.9997558…); "changed" compares
    // with what was shown, so an untouched field is never written back.
    input.value = shown(p.value);
    input.dataset.shown = input.value;
    input.oninput = () => tr.classList.toggle("changed", input.value !== input.dataset.shown);
    tbody.appendChild(tr);
  }
  // Rev 2.0.8's settings no published INFO block shows: writable, never shown.
  for (const name of cfg.write_only || []) {
    const row = rows.find((r) => r.key === name);
    if (!row) continue;
    const tr = document.createElement("tr");
    tr.innerHTML = `<td></td><td><input data-param="${name}" data-testid="param-${name}" type="number" placeholder="write-only"></td><td></td><td>–</td>`;
    tr.children[0].textContent = `${row.description} (rev ${row.since}, write-only)`;
    tr.children[0].title = `${row.name} (index ${row.index}), ${shown(row.min)}..${shown(row.max)} ${row.unit}`;
    tr.children[2].textContent = row.unit;
    const input = tr.querySelector("input");
    input.min = row.min; input.max = row.max; input.step = row.step ?? "any";
    input.dataset.shown = "";
    input.oninput = () => tr.classList.toggle("changed", input.value !== "");
    tbody.appendChild(tr);
  }
}

$("#config-reload").onclick = loadConfig;
$("#config-apply").onclick = async () => {
  if (!sameJoint(state.configFor, state.selected)) return say("The parameters of this joint are still loading.");
  const patch = {};
  for (const input of document.querySelectorAll("#config input[data-param]")) {
    const name = input.dataset.param;
    if (input.value !== input.dataset.shown) patch[name] = Number(input.value);
  }
  if (!Object.keys(patch).length) return say("Nothing changed.", "info");
  const writeOnly = new Set((state.config && state.config.write_only) || []);
  const keys = Object.keys(patch);
  const verified = keys.filter((k) => !writeOnly.has(k));
  const sent = keys.filter((k) => writeOnly.has(k));
  const said = [verified.length ? `verified: ${verified.join(", ")}` : "",
    sent.length ? `sent, not reported back by the device: ${sent.join(", ")}` : ""].filter(Boolean).join("; ");
  const done = await act(`Applied to RAM (${said}).`, () => api("PATCH", dev("/config"), patch));
  if (done) loadConfig();
};
$("#config-persist").onclick = () => {
  if (!confirm("Write the current RAM parameters to flash? They will survive power-off.")) return;
  act("Persisted to flash.", () => api("POST", dev("/config/persist")));
};
$("#change-id").onclick = async () => {
  const newId = Number($("#new-id").value);
  if (!newId) return say("Enter the new id first.");
  if (!confirm(`Change the id of joint ${state.selected.id} to ${newId}? It is stored to flash at once.`)) return;
  const done = await act(`Id changed to ${newId}.`, () => api("PUT", dev("/id"), { new_id: newId }));
  if (done) select(state.selected.bus, newId);
};

// ---------------------------------------------------------------- raw frames

/** `18:45:10.684`: 24-hour wall time with milliseconds, whatever the locale. */
function clockTime(t) {
  const two = (n) => String(n).padStart(2, "0");
  return `${two(t.getHours())}:${two(t.getMinutes())}:${two(t.getSeconds())}.${String(t.getMilliseconds()).padStart(3, "0")}`;
}

async function loadFrames() {
  if (!state.selected) return;
  const data = await act(null, () => api("GET", `buses/${encodeURIComponent(state.selected.bus)}/frames?limit=30`));
  if (!data) return;
  const tbody = $("#frames tbody");
  tbody.innerHTML = "";
  for (const f of data.frames.slice().reverse()) {
    const d = f.decoded || {};
    const summary = Object.entries(d).filter(([k]) => k !== "raw").map(([k, v]) => `${k}=${Array.isArray(v) ? "[…]" : v}`).join(" ");
    const tr = document.createElement("tr");
    tr.innerHTML = `<td>${clockTime(new Date(f.at * 1000))}</td><td>${f.direction}</td><td></td><td></td>`;
    tr.children[2].textContent = f.hex; tr.children[3].textContent = summary;
    tbody.appendChild(tr);
  }
}

setInterval(() => { if ($("#frames-live").checked) loadFrames(); }, 1000);

// ---------------------------------------------------------------- e-stop

$("#estop").onclick = async () => {
  const r = await act(null, () => api("POST", "estop"));
  if (!r) return;
  const all = (key) => r.buses.flatMap((b) => b[key]);
  const unconfirmed = all("unconfirmed");
  const again = all("disabled_again");
  let text = `Emergency stop: ${r.stopped ? "every bus stopped" : "NOT every bus stopped — see the bus list"} in ${r.elapsed_us} µs; ${all("confirmed").length} joint(s) read back disabled`;
  if (again.length) text += `; disabled again: ${again.join(", ")}`;
  if (all("still_enabled").length) text += `; STILL ENABLED: ${all("still_enabled").join(", ")}`;
  if (unconfirmed.length) text += `; not confirmed (no answer): ${unconfirmed.join(", ")}`;
  say(text + ".", r.stopped && !unconfirmed.length ? "info" : "error");
};

// ---------------------------------------------------------------- start

initMoves();
initHoming({ onHomed: (joint) => { if (sameJoint(joint, state.selected)) showCalibration(joint); } });
initCalibration({ onChanged: (joint) => { if (sameJoint(joint, state.selected)) select(joint.bus, joint.id); } });
initHands();
initRecordings();
initDoctor();
initRos2();
connect();
refreshBuses();
loadScope();
setInterval(refreshBuses, 1000);
