// Moves the daemon generates (POST /api/v1/moves, docs/motion.md): started
// from the joint panel or a hand's pose, each followed until it ends (done,
// stopped, aborted or stalled), with a Stop that holds the joints where the
// path had brought them (DELETE /api/v1/moves/{id}).

import { $, api, act, say, watch } from "./api.js";

/** One place a move is shown: a state line and a Stop button. Shows the
 *  latest move started from it; an older one's answers are ignored. */
export class MoveTracker {
  constructor(stateEl, stopButton) {
    this.stateEl = stateEl;
    this.stop = stopButton;
    this.id = null;
    this.stop.disabled = true;
    this.stop.onclick = () => this.stopMove();
  }

  /** Follows move `mv` (as POST answered it) until it ends. */
  follow(mv) {
    this.id = mv.id;
    this.show(mv);
    watch(`moves/${mv.id}`, (v) => this.show(v), (v) => v.state !== "running" || this.id !== mv.id);
  }

  /** Forgets the move shown (it goes on; only this view lets it go). */
  clear() {
    this.id = null;
    this.stateEl.textContent = "";
    delete this.stateEl.dataset.state;
    this.stop.disabled = true;
  }

  show(v) {
    if (v.id !== this.id) return;
    let text = `Move ${v.id}: ${v.state}`;
    if (v.state === "running") text += ` ${Math.round(v.progress * 100)} %`;
    if (v.reason) text += ` (${v.reason})`;
    if (v.stalled.length) text += `; stalled: ${v.stalled.map((j) => j.id).join(", ")}`;
    if (v.replaced.length) text += `; taken over: ${v.replaced.map((j) => j.id).join(", ")}`;
    this.stateEl.textContent = text;
    this.stateEl.dataset.state = v.state;
    this.stop.disabled = v.state !== "running";
  }

  async stopMove() {
    if (this.id === null) return;
    const v = await act(null, () => api("DELETE", `moves/${this.id}`));
    if (v) this.show(v);
  }
}

let panel = null;

export function initMoves() {
  panel = new MoveTracker($("#move-state"), $("#move-stop"));
  const label = () => { $("#move").textContent = Number($("#move-ms").value) > 0 ? "Smooth move" : "Move now"; };
  $("#move-ms").addEventListener("input", label);
  label();
}

/** The panel now shows `joint`: a move of another joint is no longer shown. */
export function showMovesFor() {
  panel.clear();
}

/** A smooth move of one joint to `deg` in `ms` along `method`. */
export function startMove(joint, deg, ms, method) {
  const { bus, id } = joint;
  return act(null, async () => {
    const mv = await api("POST", "moves", { joints: [{ bus, id, position_deg: deg }], duration_ms: ms, method });
    say(`Move ${mv.id}: to ${deg}° in ${mv.duration_ms} ms (${mv.method}).`, "info");
    panel.follow(mv);
    return mv;
  });
}
