// The doctor's check of a bus (POST /api/v1/buses/{bus}/doctor,
// docs/hardware.md): the port, the adapter, the line and each device
// checked against what jointd assumes, each check with its verdict and
// what to do, and the bus config the doctor proposes. The bus lends its
// port for the run (seconds, polling paused); the daemon refuses it while
// a joint of the bus is enabled (409, shown).

import { $, api, say, el } from "./api.js";

export function initDoctor() {
  $("#doctor-run").onclick = run;
  refreshBuses();
}

async function refreshBuses() {
  let data;
  try { data = await api("GET", "buses"); } catch { return; }
  const select = $("#doctor-bus");
  select.replaceChildren(...data.buses.map((b) => el("option", { value: b.name, textContent: b.name })));
}

async function run() {
  const bus = $("#doctor-bus").value;
  if (!bus) return;
  const button = $("#doctor-run");
  button.disabled = true;
  $("#doctor-state").textContent = `Checking ${bus}: its polling pauses for a few seconds…`;
  try {
    show(await api("POST", `buses/${encodeURIComponent(bus)}/doctor`));
  } catch (e) {
    $("#doctor-state").textContent = "";
    say(`Checking ${bus} failed: ${e.message}`);
  } finally {
    button.disabled = false;
  }
}

/** `sim0: warn — 14 checks (11 ok, 3 warn)`, the checks, the proposal. */
function show(report) {
  const counts = {};
  for (const c of report.checks) counts[c.verdict] = (counts[c.verdict] || 0) + 1;
  const tally = Object.entries(counts).map(([v, n]) => `${n} ${v}`).join(", ");
  $("#doctor-state").textContent = `${report.path}: ${report.verdict} — ${report.checks.length} checks (${tally})`;
  $("#doctor-state").dataset.state = report.verdict;
  $("#doctor-checks tbody").replaceChildren(...report.checks.map((c) => el("tr",
    { className: `verdict-${c.verdict}`, testid: `doctor-check-${c.id}` },
    el("td", { textContent: c.verdict }),
    el("td", { textContent: c.id.replaceAll("_", " ") }),
    el("td", { textContent: c.found }),
    el("td", { textContent: c.fix || "" }))));
  $("#doctor-checks").hidden = false;
  const toml = report.proposal?.toml;
  $("#doctor-proposal").textContent = toml || "";
  $("#doctor-proposal-section").hidden = !toml;
}
