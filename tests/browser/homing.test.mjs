// Homing and calibration from the joint panel against `jointd --sim 4` with
// a hard stop at -40° on joint 3: Home finds it (POST /api/v1/homing,
// followed until done) and the calibration shown is the one recorded; a
// calibration is set (PUT), refused with the daemon's reason, and cleared
// (DELETE).

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startDaemon, launchBrowser, openDashboard, rest, selectJoint, waitFsm, WAIT } from "./harness.mjs";

let daemon, browser, page, errors;

before(async () => {
  daemon = await startDaemon(["--sim", "4", "--sim-hard-stop", "3=-40"]);
  browser = await launchBrowser();
  ({ page, errors } = await openDashboard(browser, daemon.base));
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

const calibration = (id) => rest(daemon.base, "GET", `/api/v1/buses/sim0/devices/${id}/calibration`);
/** The error message matching `re` (shown within the wait). */
const errorShown = (re) => page.locator("#messages .error", { hasText: re }).first().textContent({ timeout: WAIT });

test("homing a joint not enabled is refused with the daemon's reason", async () => {
  await selectJoint(page, 3);
  await page.locator('[data-testid="home"]').click();
  const said = await errorShown(/homing needs joint 3/);
  assert.equal(said, "homing needs joint 3 of bus `sim0` enabled and running; it is `ready` (enable it first)");
  const dev = await rest(daemon.base, "GET", "/api/v1/buses/sim0/devices/3");
  assert.notEqual(dev.status.state, "run", "the page enabled the joint");
});

test("Home finds the hard stop and the panel shows the calibration it recorded", async () => {
  await page.locator('[data-testid="enable"]').click();
  await waitFsm(page, 3, "run");
  await page.locator("#home-speed").fill("30");
  await page.locator('[data-testid="home"]').click();
  await page.waitForFunction(() => /^Homing \d+: running/.test(document.querySelector('[data-testid="home-state"]')?.textContent || ""), null, { timeout: WAIT });
  await page.waitForFunction(() => document.querySelector('[data-testid="home-state"]')?.dataset.state === "homed", null, { timeout: WAIT });
  const text = await page.locator('[data-testid="home-state"]').textContent();
  const id = Number(text.match(/^Homing (\d+): done — homed/)?.[1]);
  assert.ok(id > 0, `state line: ${text}`);
  assert.match(text, /current limit restored$/);
  const job = await rest(daemon.base, "GET", `/api/v1/homing/${id}`);
  assert.equal(job.joints[0].state, "homed");
  assert.ok(Math.abs(job.joints[0].hard_stop_device_deg + 40) < 3, `stop at ${job.joints[0].hard_stop_device_deg}`);
  const cal = await calibration(3);
  assert.ok(cal.homed_at_ms > 0);
  await page.waitForFunction((o) => document.querySelector('[data-testid="cal-state"]')?.textContent.startsWith(`offset ${o}°, not flipped`),
    cal.offset_deg, { timeout: WAIT });
  assert.match(await page.locator('[data-testid="cal-state"]').textContent(), /found by homing/);
});

test("a calibration is set, refused when out of range, and cleared", async () => {
  await selectJoint(page, 4);
  await page.waitForFunction(() => document.querySelector('[data-testid="cal-state"]')?.textContent.startsWith("offset 0°"), null, { timeout: WAIT });
  await page.locator('[data-testid="cal-offset"]').fill("10");
  await page.locator('[data-testid="cal-flip"]').check();
  await page.locator('[data-testid="cal-low"]').fill("-30");
  await page.locator('[data-testid="cal-high"]').fill("60");
  await page.locator('[data-testid="cal-set"]').click();
  await page.waitForFunction(() => document.querySelector('[data-testid="cal-state"]')?.textContent === "offset 10°, flipped, range -30..60°", null, { timeout: WAIT });
  const set = await calibration(4);
  assert.deepEqual([set.offset_deg, set.flip, set.range_deg], [10, true, [-30, 60]]);

  await page.locator('[data-testid="cal-offset"]').fill("300");
  await page.locator('[data-testid="cal-set"]').click();
  const said = await errorShown(/255/);
  const problem = await (await fetch(`${daemon.base}/api/v1/buses/sim0/devices/4/calibration`, {
    method: "PUT", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ offset_deg: 300, flip: true, range_deg: [-30, 60] }),
  })).json();
  assert.equal(said, problem.detail, "the problem's detail is shown as the daemon gave it");
  assert.equal((await calibration(4)).offset_deg, 10, "the refused one changed nothing");

  page.once("dialog", (d) => d.accept());
  await page.locator('[data-testid="cal-clear"]').click();
  await page.waitForFunction(() => document.querySelector('[data-testid="cal-state"]')?.textContent.startsWith("offset 0°, not flipped, no range"), null, { timeout: WAIT });
  const cleared = await calibration(4);
  assert.deepEqual([cleared.offset_deg, cleared.flip, cleared.range_deg ?? null], [0, false, null]);
  assert.deepEqual(errors, []);
});
