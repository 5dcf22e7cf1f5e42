// The configured hands (`[[hand]]`, docs/motion.md): each with its joints,
// its saved poses (Go moves the hand there through the daemon's path
// generator, × deletes one) and Save current; the move a pose started is
// followed with a Stop; and its grasp controls (grasp.js). Hidden when no
// hand is configured.

import { $, api, act, say, el } from "./api.js";
import { MoveTracker } from "./moves.js";
import { graspRow } from "./grasp.js";

const trackers = new Map();     // hand name -> MoveTracker of its pose moves
const streamLines = new Map();  // hand name -> the line saying who streams to it
/** How often the page asks who streams to each hand, ms. */
const STREAMS_EVERY_MS = 1000;

export function initHands() {
  refreshHands();
  watchStreams();
}

/** Says on each hand's card which program streams setpoints to it (the
 *  LeRobot plugin, a teleop client, ROS 2 joint commands): a person about
 *  to touch the hand sees that a program drives it. */
async function watchStreams() {
  for (;;) {
    try {
      const list = await api("GET", "hands");
      for (const h of list.hands || []) showStreams(h);
    } catch (_) { /* the daemon restarting: the next read says */ }
    await new Promise((r) => setTimeout(r, STREAMS_EVERY_MS));
  }
}

function showStreams(h) {
  const line = streamLines.get(h.name);
  if (!line) return;
  const streams = h.streamed_by || [];
  line.hidden = streams.length === 0;
  line.textContent = streams.map((s) => {
    const who = s.name || (s.via === "ros2" ? "ROS 2" : "a WebSocket client");
    const via = s.via === "ros2" ? "ROS 2" : `WebSocket client ${s.client}`;
    const idle = s.idle_ms > 1000 ? `, idle ${Math.round(s.idle_ms / 1000)} s` : "";
    return `Driven by ${who} (${via}${idle}): ${s.joints.join(", ")}`;
  }).join("; ");
}

const handPath = (hand, name) => `hands/${encodeURIComponent(hand)}/poses/${encodeURIComponent(name)}`;

async function refreshHands() {
  let list;
  try { list = await api("GET", "hands"); } catch (e) { say(`Reading the hands failed: ${e.message}`); return; }
  const hands = list.hands || [];
  $("#poses-section").hidden = hands.length === 0;
  const box = $("#poses");
  box.textContent = "";
  for (const h of hands) box.append(handView(h));
}

function handView(h) {
  const joints = h.joints.map((j) => `${j.name} (${j.bus}/${j.id})`).join(", ");
  const card = el("div", { className: "hand", testid: `hand-${h.name}` },
    el("div", { className: "row" }, el("strong", { textContent: h.name }), el("span", { className: "hint", textContent: joints })));
  const streams = el("div", { className: "streamed", testid: `hand-streams-${h.name}`, hidden: true });
  streamLines.set(h.name, streams);
  showStreams(h);
  card.append(streams);
  const poses = el("div", { className: "row" });
  if (!h.poses.length) poses.append(el("span", { className: "hint", textContent: "no saved poses" }));
  for (const name of h.poses) poses.append(poseChip(h.name, name));
  card.append(poses, saveRow(h.name), moveRow(h.name), graspRow(h.name));
  return card;
}

/** A pose: its name goes there, × deletes it. */
function poseChip(hand, name) {
  const go = el("button", { textContent: name, needs: "operate", title: `Move ${hand} to ${name}`, testid: `pose-${hand}-${name}`, onclick: () => goPose(hand, name) });
  const del = el("button", { textContent: "×", needs: "operate", className: "quiet", title: `Delete pose ${name}`,
    testid: `pose-delete-${hand}-${name}`, onclick: () => deletePose(hand, name) });
  return el("span", { className: "chip" }, go, del);
}

function saveRow(hand) {
  const input = el("input", { placeholder: "pose name", size: 10, testid: `pose-name-${hand}` });
  const save = el("button", { textContent: "Save current", needs: "operate", testid: `pose-save-${hand}`, onclick: () => savePose(hand, input.value.trim()) });
  return el("div", { className: "row" }, input, save);
}

/** The hand's latest pose move and its Stop: made once per hand and moved
 *  into each refreshed card, so a move followed goes on being shown. */
function moveRow(hand) {
  if (!trackers.has(hand)) {
    const state = el("span", { className: "move-state", testid: `hand-move-state-${hand}` });
    const stop = el("button", { textContent: "Stop", needs: "operate", testid: `hand-move-stop-${hand}` });
    trackers.set(hand, new MoveTracker(state, stop));
  }
  const t = trackers.get(hand);
  return el("div", { className: "row" }, t.stateEl, t.stop);
}

async function savePose(hand, name) {
  if (!name) return say("Name the pose first.");
  const saved = await act(null, () => api("PUT", handPath(hand, name), { from_current: true }));
  if (saved) {
    say(`Pose ${name} of ${hand} saved.`, "info");
    refreshHands();
  }
}

async function deletePose(hand, name) {
  if (!confirm(`Delete pose ${name} of ${hand}?`)) return;
  const gone = await act(`Pose ${name} of ${hand} deleted.`, () => api("DELETE", handPath(hand, name)));
  if (gone) refreshHands();
}

/** Goes with the duration and shape next to the panel's target (800 ms by default). */
function goPose(hand, name) {
  const ms = Number($("#move-ms").value) || 800;
  return act(null, async () => {
    const mv = await api("POST", `${handPath(hand, name)}/go`, { duration_ms: ms, method: $("#move-method").value });
    say(`Move ${mv.id}: ${hand} to pose ${name} in ${mv.duration_ms} ms.`, "info");
    trackers.get(hand).follow(mv);
  });
}
