// Recordings (MCAP files in the daemon's recordings directory,
// docs/recordings.md): Record in the header starts one and stops it; the
// Recordings list shows every one since the daemon started, each finished
// one with a download link. Behind a token the link fetches the file with
// it (a plain link carries no Authorization header).

import { $, API, api, act, say, el, authHeaders } from "./api.js";

const REFRESH_MS = 2000;
let recording = null;           // the one Record started, while it runs

export function initRecordings() {
  $("#record").onclick = () => (recording ? stop() : start());
  refreshList();
  setInterval(refreshList, REFRESH_MS);
}

async function start() {
  const r = await act(null, () => api("POST", "recordings", {}));
  if (!r) return;
  recording = r;
  $("#record").textContent = "■ Stop recording";
  $("#record").classList.add("on");
  $("#recording-file").hidden = true;
  say(`Recording ${r.id} to ${r.file}.`, "info");
  refreshList();
}

async function stop() {
  const id = recording.id;
  const r = await act(null, () => api("DELETE", `recordings/${id}`));
  recording = null;
  $("#record").textContent = "● Record";
  $("#record").classList.remove("on");
  refreshList();
  if (!r) return;
  const total = Object.values(r.messages).reduce((a, b) => a + b, 0);
  say(`Recording ${id} finished: ${total} messages in ${r.file}.`, "info");
  linkTo($("#recording-file"), r);
  $("#recording-file").hidden = false;
}

/** Makes `a` download recording `r`'s file. */
function linkTo(a, r) {
  a.href = `${API}/recordings/${r.id}/file`;
  a.download = r.file;
  a.onclick = (ev) => {
    if (!authHeaders().Authorization) return;   // the plain link works
    ev.preventDefault();
    act(null, () => downloadWithToken(a.href, r.file));
  };
  return a;
}

async function downloadWithToken(url, file) {
  const res = await fetch(url, { headers: authHeaders() });
  if (!res.ok) {
    let body = null;
    try { body = await res.json(); } catch { /* not a problem body */ }
    throw new Error(body && body.detail ? body.detail : `HTTP ${res.status}`);
  }
  const a = el("a", { href: URL.createObjectURL(await res.blob()), download: file });
  a.click();
  URL.revokeObjectURL(a.href);
}

async function refreshList() {
  let list;
  try {
    list = await api("GET", "recordings");
    $("#recordings-error").textContent = "";
  } catch (e) {
    // Shown where the list is, not as a message every refresh.
    $("#recordings-error").textContent = `Cannot read the recordings: ${e.message}`;
    return;
  }
  const tbody = $("#recordings tbody");
  tbody.textContent = "";
  for (const r of list.recordings.slice().reverse()) tbody.append(row(r));
  $("#recordings-empty").hidden = list.recordings.length > 0;
}

function row(r) {
  const total = Object.values(r.messages).reduce((a, b) => a + b, 0);
  const secs = r.ended_ms ? ((r.ended_ms - r.started_ms) / 1000).toFixed(1) : "–";
  const file = r.state === "finished"
    ? linkTo(el("a", { textContent: r.file, testid: `recording-download-${r.id}` }), r)
    : el("span", { textContent: r.file });
  const state = el("td", { textContent: r.state + (r.error ? `: ${r.error}` : ""), className: r.state === "failed" ? "fault" : "" });
  const cells = [el("td", { textContent: r.id }), state, el("td", {}, file), el("td", { textContent: r.buses.join(", ") }),
    el("td", { textContent: secs }), el("td", { textContent: total }), el("td", { textContent: r.lost })];
  return el("tr", { testid: `recording-${r.id}` }, ...cells);
}
