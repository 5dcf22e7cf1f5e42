// Grasping with a hand (POST /api/v1/hands/{hand}/grasp, docs/grasping.md):
// its fingers close at the set speed until each feels contact, then hold
// with the set q current. Grasp starts it, Release opens the fingers back
// to where they started, Stop holds them where they are; the job is read
// live while it runs: each finger's state, contact, contact angle and
// current. The daemon does all of it (and refuses what it cannot do: shown).

import { api, act, say, el, watch } from "./api.js";

const POLL_MS = 150;
const rows = new Map();       // hand name -> its GraspRow (kept across card refreshes)

/** The hand's grasp controls, made once per hand and moved into each
 *  refreshed card, so a grasp followed goes on being shown. */
export function graspRow(hand) {
  if (!rows.has(hand)) rows.set(hand, new GraspRow(hand));
  return rows.get(hand).root;
}

const fixed = (v, digits) => (v === null || v === undefined ? "–" : v.toFixed(digits));

class GraspRow {
  constructor(hand) {
    this.hand = hand;
    this.job = null;          // the grasp followed
    const id = (what) => `grasp-${what}-${hand}`;
    this.speed = el("input", { type: "number", className: "short", min: 1, max: 180, step: 1, value: 30, testid: id("speed"),
      title: "Closing speed at the output, °/s" });
    this.hold = el("input", { type: "number", className: "short", min: 0.01, step: 0.01, value: 0.2, testid: id("hold"),
      title: "The force each finger holds with, as a q current, A" });
    this.state = el("span", { className: "move-state", testid: id("state") });
    this.body = el("tbody");
    this.table = el("table", { className: "grasp", hidden: true, testid: id("fingers") },
      el("thead", {}, el("tr", {},
        el("th", { textContent: "finger" }), el("th", { textContent: "state" }), el("th", { textContent: "contact" }),
        th("contact", "°"), th("current", "A"))),
      this.body);
    this.root = el("div", { className: "grasp-box" },
      el("div", { className: "row" },
        el("button", { textContent: "Grasp", needs: "operate", testid: `grasp-${hand}`, onclick: () => this.start() }),
        el("button", { textContent: "Release", needs: "operate", testid: id("release"), onclick: () => this.end("release") }),
        el("button", { textContent: "Stop", needs: "operate", testid: id("stop"), onclick: () => this.end("stop") }),
        el("label", {}, "°/s ", this.speed),
        el("label", {}, "hold A ", this.hold),
        this.state),
      this.table);
  }

  async start() {
    const body = { speed_dps: Number(this.speed.value), hold_current_a: Number(this.hold.value) };
    const started = await act(null, () => api("POST", `hands/${encodeURIComponent(this.hand)}/grasp`, body));
    if (!started) return;
    say(`Grasp ${started.id} of ${this.hand} started.`, "info");
    this.job = started.id;
    this.show(started);
    await watch(`grasps/${started.id}`, (v) => this.show(v), (v) => v.state !== "running" || this.job !== started.id, POLL_MS);
  }

  /** Release or stop the grasp shown; the daemon answers once every finger ended. */
  async end(how) {
    if (this.job === null) return say(`No grasp of ${this.hand} to ${how}.`);
    const job = this.job;
    const body = how === "release" ? {} : undefined;
    const ended = await act(null, () => api("POST", `grasps/${job}/${how}`, body));
    if (ended) this.show(ended);
  }

  /** `Grasp 3: running`, and a row per finger. */
  show(v) {
    if (v.id !== this.job) return;
    this.state.textContent = `Grasp ${v.id}: ${v.state}`;
    this.state.dataset.state = v.state;
    this.table.hidden = false;
    this.body.replaceChildren(...v.fingers.map((f) => fingerRow(this.hand, f)));
  }
}

function th(name, unit) {
  return el("th", {}, `${name} `, el("small", { textContent: unit }));
}

/** One finger: its cells carry the API's field names (`data-field`). */
function fingerRow(hand, f) {
  const cell = (field, text, title = "") => {
    const td = el("td", { textContent: text, title });
    td.dataset.field = field;
    return td;
  };
  const row = el("tr", { testid: `grasp-finger-${hand}-${f.joint}` },
    cell("joint", f.joint, `${f.bus}/${f.id}`),
    cell("state", f.state, f.reason || ""),
    cell("contact", f.contact ? "yes" : "no"),
    cell("contact_deg", fixed(f.contact_deg, 1)),
    cell("q_current_a", fixed(f.q_current_a, 3)));
  row.dataset.state = f.state;
  // Ended badly, or ended without its previous current limit confirmed back.
  if (["aborted", "failed"].includes(f.state) || (!live(f.state) && !f.current_limit_restored)) row.classList.add("fault");
  return row;
}

/** Still under the grasp's control (the limits are restored once it is not). */
const live = (state) => ["starting", "closing", "holding", "no_contact", "lost", "releasing"].includes(state);
