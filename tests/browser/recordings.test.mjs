// Recordings and the ROS 2 bridge's status in the dashboard: Record starts
// and stops an MCAP recording, the list shows it with a link that
// downloads the file (its first bytes the MCAP magic); the bridge's status
// is shown as GET /api/v1/ros2 gives it.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { startDaemon, launchBrowser, openDashboard, rest, WAIT } from "./harness.mjs";

/** The magic every MCAP file starts with: 0x89 "MCAP0" CR LF. */
const MCAP_MAGIC = Buffer.from([0x89, 0x4d, 0x43, 0x41, 0x50, 0x30, 0x0d, 0x0a]);
let daemon, browser, page, errors;

before(async () => {
  daemon = await startDaemon(["--sim", "4"], "");
  browser = await launchBrowser();
  ({ page, errors } = await openDashboard(browser, daemon.base));
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

test("a recording started and stopped is listed and its link downloads the MCAP file", async () => {
  await page.locator('[data-testid="record"]').click();
  const started = await page.locator("#messages .info", { hasText: /^Recording \d+ to / }).first().textContent({ timeout: WAIT });
  const id = Number(started.match(/^Recording (\d+)/)[1]);
  const row = page.locator(`[data-testid="recording-${id}"]`);
  await row.locator("td", { hasText: /^recording$/ }).waitFor({ timeout: WAIT });
  // Stopped once something was written, so the file has joint states.
  const deadline = Date.now() + WAIT;
  while (((await rest(daemon.base, "GET", `/api/v1/recordings/${id}`)).messages["/sim0/joint_states"] ?? 0) === 0) {
    assert.ok(Date.now() < deadline, "nothing recorded");
    await page.waitForTimeout(50);
  }
  await page.locator('[data-testid="record"]').click();
  const link = page.locator(`[data-testid="recording-download-${id}"]`);
  await link.waitFor({ timeout: WAIT });
  assert.match(await row.textContent(), /finished/);
  const [download] = await Promise.all([page.waitForEvent("download", { timeout: WAIT }), link.click()]);
  const done = await rest(daemon.base, "GET", `/api/v1/recordings/${id}`);
  assert.equal(download.suggestedFilename(), done.file);
  const bytes = await readFile(await download.path());
  assert.ok(bytes.length > MCAP_MAGIC.length * 2, `${bytes.length} bytes`);
  assert.deepEqual(bytes.subarray(0, 8), MCAP_MAGIC);
  assert.deepEqual(bytes.subarray(-8), MCAP_MAGIC, "a complete file ends with the magic too");
});

test("the ROS 2 bridge's status is shown as the daemon reports it", async () => {
  const status = await rest(daemon.base, "GET", "/api/v1/ros2");
  const field = (name) => page.locator(`[data-testid="ros2-${name}"]`).textContent({ timeout: WAIT });
  assert.equal(await field("enabled"), status.enabled ? "yes" : "no");
  assert.equal(await field("connected"), status.connected ? "yes" : "no");
  assert.match(await field("built"), status.built ? /^yes$/ : /^no /);
  for (const counter of ["joint_states", "commands_applied", "commands_dropped", "publish_errors"]) {
    assert.equal(await field(counter), String(status[counter]), counter);
  }
  // Read-only: no control in its section.
  assert.equal(await page.locator('[data-testid="ros2-section"] :is(button, input, select)').count(), 0);
  assert.deepEqual(errors, []);
});
