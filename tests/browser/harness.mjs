// What the dashboard's browser tests share: a daemon on a free port (its
// first stdout line names it), Debian's headless Chromium, REST calls, and
// waits on conditions (never fixed sleeps).

import assert from "node:assert/strict";
import { spawn } from "node:child_process";
import { mkdtempSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { chromium } from "playwright-core";

export const ROOT = new URL("../../", import.meta.url).pathname;
const BIN = process.env.JOINTD_BIN || `${ROOT}target/debug/jointd`;
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";
export const WAIT = 20_000;

/** The daemon's first stdout line is `listening on <url>` (port 0 picks a free port). */
function listeningUrl(child) {
  return new Promise((resolve, reject) => {
    let buf = "";
    const timer = setTimeout(() => reject(new Error("jointd did not report its address")), WAIT);
    child.stdout.on("data", (chunk) => {
      buf += chunk;
      const m = buf.match(/^listening on (\S+)/m);
      if (m) { clearTimeout(timer); resolve(m[1]); }
    });
    child.once("exit", (code) => reject(new Error(`jointd exited early with ${code}`)));
  });
}

async function waitReady(url, token) {
  const headers = token ? { Authorization: `Bearer ${token}` } : {};
  const deadline = Date.now() + WAIT;
  while (Date.now() < deadline) {
    try {
      if ((await fetch(`${url}/readyz`, { headers })).ok) return;
    } catch { /* not listening yet */ }
    await new Promise((r) => setTimeout(r, 100));
  }
  throw new Error(`daemon not ready at ${url}`);
}

/** Starts `jointd` with `args` (plus a free port and, with `config`, that
 *  TOML text in a fresh directory, its `state_dir` beside it); `token`:
 *  one the daemon takes, for the readiness check. A daemon that does not
 *  get ready is stopped, so the test process can end. The directory is
 *  also its TMPDIR (the simulator's pty link, default recordings), and is
 *  removed once the daemon has exited. */
export async function startDaemon(args, config, token) {
  const all = [...args, "--listen", "127.0.0.1:0"];
  // Serves web/ from that folder instead of the embedded copy: edits show
  // without a rebuild (and an older copy can be checked against the tests).
  if (process.env.JOINTD_WEB_DIR) all.push("--web-dir", process.env.JOINTD_WEB_DIR);
  const dir = mkdtempSync(join(tmpdir(), "jointd-browser-"));
  if (config !== undefined) {
    const file = join(dir, "jointd.toml");
    writeFileSync(file, `state_dir = "${join(dir, "state")}"\n\n${config}`);
    all.push("--config", file);
  }
  const child = spawn(BIN, all, {
    stdio: ["ignore", "pipe", "inherit"],
    env: { ...process.env, TMPDIR: dir },
  });
  const exited = new Promise((r) => child.once("exit", r));
  const removeDir = () => rmSync(dir, { recursive: true, force: true });
  let base;
  try {
    base = await listeningUrl(child);
    await waitReady(base, token);
  } catch (e) {
    child.kill("SIGKILL");
    await exited;
    removeDir();
    throw e;
  }
  const stop = async () => {
    child.kill("SIGTERM");
    await exited;
    removeDir();
  };
  return { base, stop };
}

export function launchBrowser() {
  return chromium.launch({
    executablePath: CHROMIUM,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
      "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic"],
  });
}

/** A page of the dashboard at `viewport`; a script error fails the test
 *  that reads `errors`. */
export async function openDashboard(browser, base, viewport = { width: 1400, height: 900 }) {
  const page = await browser.newPage({ viewport, acceptDownloads: true });
  const errors = [];
  page.on("pageerror", (e) => { errors.push(e.message); console.error("page error:", e.message); });
  await page.goto(base);
  return { page, errors };
}

/** A REST call that must succeed. */
export async function rest(base, method, path, body) {
  const r = await fetch(`${base}${path}`, {
    method, headers: { "Content-Type": "application/json" },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const data = await r.json();
  assert.ok(r.ok, `${method} ${path}: ${JSON.stringify(data)}`);
  return data;
}

/** Waits until joint `id` of sim0 shows `fsm` in the device table. */
export function waitFsm(page, id, fsm) {
  return page.waitForFunction(([id, fsm]) =>
    document.querySelector(`[data-testid="device-row-sim0-${id}"] td[data-field="state"]`)?.textContent === fsm,
  [id, fsm], { timeout: WAIT });
}

/** Waits until joint `id` of sim0's angle in the table is within `tol` of `deg`. */
export function waitAngle(page, id, deg, tol = 1) {
  return page.waitForFunction(([id, deg, tol]) => {
    const v = Number(document.querySelector(`[data-testid="device-row-sim0-${id}"] td[data-field="angle_deg"]`)?.textContent);
    return Math.abs(v - deg) < tol;
  }, [id, deg, tol], { timeout: WAIT });
}

/** Waits until the selected joint's parameter form shows; on a timeout the
 *  error says what the bus counted (a config read the device did not
 *  answer shows as timeouts and retries; the page's own message is gone
 *  by then). */
export async function waitConfig(page, base) {
  try {
    await page.locator('[data-testid="param-pos_kp"]').waitFor({ state: "visible", timeout: WAIT });
  } catch (e) {
    const bus = await fetch(`${base}/api/v1/buses/sim0`).then((r) => r.json()).catch(() => ({}));
    const c = bus.counters ?? {};
    const counted = ["timeouts", "retries", "crc_errors", "skipped_bytes", "unsolicited"].map((k) => `${k} ${c[k]}`).join(", ");
    throw new Error(`${e.message}\nbus sim0: ${counted}`);
  }
}

/** Selects joint `id` of sim0 in the device table; its panel shows. */
export async function selectJoint(page, id) {
  await page.locator(`[data-testid="device-row-sim0-${id}"]`).click({ timeout: WAIT });
  await page.waitForFunction((id) => document.querySelector("#panel-title")?.textContent.startsWith(`${id} `), id, { timeout: WAIT });
}
