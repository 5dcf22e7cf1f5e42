// The dashboard in real headless Chromium (Debian's), driven by playwright-core,
// against `jointd --sim 16`: live device table, a slider moving a joint, a
// configuration change applied and read back, e-stop disabling everything.
// Screenshots go to $SCREENSHOT_DIR (default target/screenshots/ in the repo),
// never into tracked files: dashboard.png there is the page at the 1366×768 of
// a laptop, the picture the README shows once copied over docs/dashboard.png.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { createServer } from "node:http";
import { mkdirSync } from "node:fs";
import { ROOT, WAIT, launchBrowser, rest as restAt, startDaemon, waitConfig } from "./harness.mjs";

const SHOTS = process.env.SCREENSHOT_DIR || `${ROOT}target/screenshots`;
/** A common laptop screen: the joint panel must be usable without scrolling. */
const VIEWPORT = { width: 1366, height: 768 };

let daemon, browser, page, base;

const rest = (method, path, body) => restAt(base, method, path, body);

const cell = (id, field) => page.locator(`[data-testid="device-row-sim0-${id}"] td[data-field="${field}"]`);

before(async () => {
  mkdirSync(SHOTS, { recursive: true });
  // Joints 9–16 run rev 2.0.8 firmware, 1–8 V2.0.1: a mixed bus, as in the field.
  // A hand of joint 1, its poses in a state file of a fresh directory.
  daemon = await startDaemon(["--sim", "16", "--sim-firmware", "9-16=2.0.8"],
    '[[hand]]\nname = "left"\njoints = [{ bus = "sim0", ids = 1, names = ["thumb"] }]\n');
  base = daemon.base;
  browser = await launchBrowser();
  page = await browser.newPage({ viewport: VIEWPORT });
  page.on("pageerror", (e) => console.error("page error:", e.message));
  await page.goto(base);
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

test("the device table lists the simulated joints with live values", async () => {
  const rows = page.locator('[data-testid^="device-row-sim0-"]');
  await page.waitForFunction(() => document.querySelectorAll('[data-testid^="device-row-sim0-"]').length === 16, null, { timeout: WAIT });
  assert.equal(await rows.count(), 16);
  await page.waitForFunction(() => {
    const td = document.querySelector('[data-testid="device-row-sim0-16"] td[data-field="vbus_v"]');
    return td && td.textContent !== "–";
  }, null, { timeout: WAIT });
  const vbus = Number(await cell(16, "vbus_v").textContent());
  assert.ok(vbus > 5 && vbus < 60, `plausible bus voltage, got ${vbus}`);
  assert.equal(await cell(1, "state").textContent(), "ready");
  // Live: the telemetry age keeps being refreshed.
  const ages = new Set();
  for (let i = 0; i < 10 && ages.size < 2; i++) {
    ages.add(await cell(1, "age_ms").textContent());
    await page.waitForTimeout(120);
  }
  assert.ok(ages.size >= 2, "the table updates");
  await page.screenshot({ path: `${SHOTS}/devices.png`, fullPage: true });
});

test("moving the slider moves the joint", async () => {
  await page.locator('[data-testid="device-row-sim0-1"]').click();
  await page.locator('[data-testid="device-panel"]').waitFor({ state: "visible" });
  await page.locator('[data-testid="enable"]').click();
  await page.waitForFunction(() => document.querySelector('[data-testid="device-row-sim0-1"] td[data-field="state"]')?.textContent === "run", null, { timeout: WAIT });
  await page.locator("#speed-limit").fill("200");
  await page.locator('[data-testid="target-slider"]').fill("30");
  await page.waitForFunction(() => {
    const v = Number(document.querySelector('[data-testid="device-row-sim0-1"] td[data-field="angle_deg"]')?.textContent);
    return v > 25;
  }, null, { timeout: WAIT });
  const angle = Number(await cell(1, "angle_deg").textContent());
  assert.ok(Math.abs(angle - 30) < 5, `joint 1 near 30°, at ${angle}`);
  await page.waitForTimeout(300); // let the plot draw the move
  await page.screenshot({ path: `${SHOTS}/joint-panel.png`, fullPage: true });
  await page.evaluate(() => window.scrollTo(0, 0));
  await page.screenshot({ path: `${SHOTS}/dashboard.png` });
});

test("a move with a duration goes through the daemon's path generator", async () => {
  await page.locator('[data-testid="move-ms"]').fill("400");
  await page.locator('[data-testid="move-method"]').selectOption("trapezoid");
  await page.locator('[data-testid="target-number"]').fill("-20");
  await page.locator('[data-testid="move"]').click();
  await page.locator("#messages .info", { hasText: /^Move \d+: to -20° in 400 ms \(trapezoid\)\.$/ }).waitFor({ timeout: WAIT });
  await page.waitForFunction(() => {
    const v = Number(document.querySelector('[data-testid="device-row-sim0-1"] td[data-field="angle_deg"]')?.textContent);
    return Math.abs(v + 20) < 1;
  }, null, { timeout: WAIT });
  // The daemon reports the move done.
  const state = await page.evaluate(async () => (await (await fetch("/api/v1/moves/1")).json()).state);
  assert.equal(state, "done");
  await page.locator('[data-testid="move-ms"]').fill("");
});

/** Waits until joint `id`'s angle in the table is within 1° of `deg`. */
async function angleNear(id, deg) {
  await page.waitForFunction(([id, deg]) => {
    const v = Number(document.querySelector(`[data-testid="device-row-sim0-${id}"] td[data-field="angle_deg"]`)?.textContent);
    return Math.abs(v - deg) < 1;
  }, [id, deg], { timeout: WAIT });
}

test("a hand's pose is saved from where it is and gone back to", async () => {
  await page.locator('[data-testid="poses"]').waitFor({ state: "visible", timeout: WAIT });
  await page.locator('[data-testid="pose-name-left"]').fill("bent");
  await page.locator('[data-testid="pose-save-left"]').click();
  const pose = page.locator('[data-testid="pose-left-bent"]');
  await pose.waitFor({ timeout: WAIT });
  // Somewhere else, then back to the pose (-20°, where the last test left it).
  await page.locator('[data-testid="target-number"]').fill("10");
  await page.locator('[data-testid="move"]').click();
  await angleNear(1, 10);
  await page.locator('[data-testid="move-ms"]').fill("300");
  await pose.click();
  await page.locator("#messages .info", { hasText: /^Move \d+: left to pose bent in 300 ms\.$/ }).waitFor({ timeout: WAIT });
  await angleNear(1, -20);
  await page.locator('[data-testid="move-ms"]').fill("");
});

test("Record starts a recording, stops it, and the file downloads", async () => {
  await page.locator('[data-testid="record"]').click();
  await page.locator("#messages .info", { hasText: /^Recording \d+ to rec-\d+-\d+\.mcap\.$/ }).waitFor({ timeout: WAIT });
  const running = (await rest("GET", "/api/v1/recordings")).recordings.filter((r) => r.state === "recording");
  assert.equal(running.length, 1);
  await new Promise((r) => setTimeout(r, 500));
  await page.locator('[data-testid="record"]').click();
  await page.locator("#messages .info", { hasText: /^Recording \d+ finished: \d+ messages/ }).waitFor({ timeout: WAIT });
  const done = await rest("GET", `/api/v1/recordings/${running[0].id}`);
  assert.equal(done.state, "finished");
  assert.ok(done.messages["/sim0/joint_states"] > 0, JSON.stringify(done.messages));
  const [download] = await Promise.all([
    page.waitForEvent("download", { timeout: WAIT }),
    page.locator('[data-testid="recording-file"]').click(),
  ]);
  assert.equal(download.suggestedFilename(), done.file);
});

test("at 1366×768 the joint panel's controls are in view without scrolling", async () => {
  await page.evaluate(() => window.scrollTo(0, 0));
  for (const sel of ['[data-testid="device-panel"] h2', '[data-testid="enable"]', '[data-testid="target-slider"]',
    '[data-testid="target-number"]', '[data-testid="move-ms"]', '[data-testid="move-method"]',
    '[data-testid="move"]', "#plot"]) {
    const box = await page.locator(sel).boundingBox();
    assert.ok(box, `${sel} is laid out`);
    assert.ok(box.y >= 0 && box.y + box.height <= VIEWPORT.height && box.x + box.width <= VIEWPORT.width,
      `${sel} at ${JSON.stringify(box)} is outside ${VIEWPORT.width}×${VIEWPORT.height}`);
  }
});

test("the target box shows a long number whole", async () => {
  const input = page.locator('[data-testid="target-number"]');
  await input.fill("-123.456");
  const fits = await input.evaluate((el) => el.scrollWidth <= el.clientWidth);
  assert.ok(fits, "the number is cut off");
  await input.fill("30");
});

test("the frame log is live by default, with 24-hour times", async () => {
  assert.equal(await page.locator("#frames-live").isChecked(), true, "live is off on load");
  const first = () => page.locator("#frames tbody tr td:first-child").first().textContent();
  await page.locator("#frames tbody tr").first().waitFor({ timeout: WAIT });
  const before = await first();
  assert.match(before, /^([01]\d|2[0-3]):[0-5]\d:[0-5]\d\.\d{3}$/, `time cell ${before}`);
  // Live: newer frames replace the shown ones without a click.
  await page.waitForFunction((b) => document.querySelector("#frames tbody tr td")?.textContent !== b, before, { timeout: WAIT });
});

test("a configuration change is applied and read back", async () => {
  const input = page.locator('[data-testid="param-pos_kp"]');
  await input.waitFor({ state: "visible" });
  const before = Number(await input.inputValue());
  const wanted = before === 0.5 ? 0.75 : 0.5;
  await input.fill(String(wanted));
  await page.locator('[data-testid="config-apply"]').click();
  await page.locator("#messages .info", { hasText: "Applied to RAM" }).waitFor({ timeout: WAIT });
  await page.locator("#config-reload").click();
  await page.waitForFunction((w) => Math.abs(Number(document.querySelector('[data-testid="param-pos_kp"]')?.value) - w) < 1e-3, wanted, { timeout: WAIT });
  const cfg = await rest("GET", "/api/v1/buses/sim0/devices/1/config");
  // Q12 steps: 0.5 and 0.75 are exact.
  assert.equal(cfg.pos_kp.value, wanted, "the device reads back the new gain");
  await page.screenshot({ path: `${SHOTS}/config.png`, fullPage: true });
});

test("the panel shows each joint's firmware revision and offers what it has", async () => {
  await page.locator('[data-testid="device-row-sim0-9"]').click();
  await page.waitForFunction(() => /protocol rev 2\.0\.8 \(detected\) · serial /.test(document.querySelector('[data-testid="panel-firmware"]')?.textContent || ""), null, { timeout: WAIT });
  assert.equal(await page.locator('[data-testid="mode-current"]').isDisabled(), false, "current mode offered on 2.0.8");
  const limit = page.locator('[data-testid="param-spd_limit_rpm"]');
  await limit.waitFor({ state: "visible", timeout: WAIT });
  assert.equal(await limit.getAttribute("placeholder"), "write-only");
  await limit.fill("10000");
  await page.locator('[data-testid="config-apply"]').click();
  await page.locator("#messages .info", { hasText: "sent, not reported back by the device: spd_limit_rpm" }).waitFor({ timeout: WAIT });
  await page.screenshot({ path: `${SHOTS}/firmware-2.0.8.png`, fullPage: true });

  await page.locator('[data-testid="device-row-sim0-1"]').click();
  // Joint 9's rows go the moment another joint is selected, before its own
  // arrive: Apply never writes what was shown for one joint to another.
  assert.equal(await page.locator('[data-testid="param-spd_limit_rpm"]').count(), 0, "joint 9's rows are gone at once");
  await page.waitForFunction(() => /protocol rev 2\.0\.1 \(detected\)$/.test(document.querySelector('[data-testid="panel-firmware"]')?.textContent || ""), null, { timeout: WAIT });
  assert.equal(await page.locator('[data-testid="mode-current"]').isDisabled(), true, "no current mode on 2.0.1");
  await waitConfig(page, daemon.base);
  assert.equal(await page.locator('[data-testid="param-spd_limit_rpm"]').count(), 0, "no rev 2.0.8 rows on 2.0.1");
});

test("e-stop disables every joint", async () => {
  await rest("POST", "/api/v1/buses/sim0/control/enable", {});
  await page.waitForFunction(() => [...document.querySelectorAll('[data-testid^="device-row-sim0-"] td[data-field="state"]')]
    .every((td) => td.textContent === "run"), null, { timeout: WAIT });
  await page.locator('[data-testid="estop"]').click();
  await page.waitForFunction(() => [...document.querySelectorAll('[data-testid^="device-row-sim0-"] td[data-field="state"]')]
    .every((td) => td.textContent === "ready"), null, { timeout: WAIT });
  await page.locator("#messages .info", { hasText: "Emergency stop" }).first().waitFor({ timeout: WAIT });
  await page.screenshot({ path: `${SHOTS}/estop.png`, fullPage: true });
});

// A page of another origin the user happens to visit. It sends the
// requests a browser lets any page send (no-cors POSTs, a WebSocket); the
// daemon must refuse them all and the joints stay disabled.
test("a page of another origin cannot move a joint", async () => {
  const evil = createServer((_, res) => {
    res.writeHead(200, { "Content-Type": "text/html" });
    res.end("<!doctype html><title>elsewhere</title>");
  });
  await new Promise((r) => evil.listen(0, "localhost", r));
  const other = await browser.newPage();
  try {
    await other.goto(`http://localhost:${evil.address().port}/`);
    const outcome = await other.evaluate(async (api) => {
      const post = (path, init = {}) => fetch(`${api}${path}`, { method: "POST", mode: "no-cors", ...init })
        .then(() => "sent", () => "failed");
      await post("/api/v1/buses/sim0/devices/5/enable");
      await post("/api/v1/buses/sim0/control/enable", { body: "{}", headers: { "Content-Type": "text/plain" } });
      await post("/api/v1/buses/sim0/devices/5/rezero", { body: "a=b", headers: { "Content-Type": "application/x-www-form-urlencoded" } });
      const ws = await new Promise((resolve) => {
        const sock = new WebSocket(`${api.replace("http", "ws")}/api/v1/ws`);
        sock.onopen = () => {
          sock.send(JSON.stringify({ type: "setpoints", seq: 1, targets: [{ id: 5, position_deg: 40 }] }));
          resolve("opened");
        };
        sock.onerror = () => resolve("refused");
      });
      return ws;
    }, base);
    assert.equal(outcome, "refused", "the WebSocket opened from another origin");
    const all = await rest("GET", "/api/v1/buses/sim0/devices");
    assert.ok(all.devices.every((d) => d.state === "ready"), JSON.stringify(all.devices.map((d) => d.state)));
  } finally {
    await other.close();
    evil.close();
  }
});
