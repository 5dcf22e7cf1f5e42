// The doctor's check of a bus from the dashboard against `jointd --sim 4`:
// Check shows each check with its verdict and the proposed bus config;
// with a joint enabled the daemon refuses it and the page says why.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startDaemon, launchBrowser, openDashboard, rest, WAIT } from "./harness.mjs";

let daemon, browser, page, errors;

before(async () => {
  daemon = await startDaemon(["--sim", "4"]);
  browser = await launchBrowser();
  ({ page, errors } = await openDashboard(browser, daemon.base));
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

test("Check shows the doctor's checks of the bus and the config it proposes", async () => {
  await page.locator('[data-testid="doctor-bus"] option[value="sim0"]').waitFor({ state: "attached", timeout: WAIT });
  await page.locator('[data-testid="doctor-run"]').click();
  const devices = page.locator('[data-testid="doctor-check-devices"]');
  await devices.waitFor({ timeout: 60_000 });
  assert.match(await devices.textContent(), /^ok/);
  assert.match(await page.locator('[data-testid="doctor-state"]').textContent(), /\d+ checks \(/);
  assert.match(await page.locator('[data-testid="doctor-proposal"]').textContent(), /^\[\[bus\]\]/m);
  assert.deepEqual(errors, []);
});

test("with a joint enabled the check is refused and the page says why", async () => {
  await rest(daemon.base, "POST", "/api/v1/buses/sim0/devices/1/enable");
  await page.locator('[data-testid="doctor-run"]').click();
  const said = await page.locator("#messages .error", { hasText: /^Checking sim0 failed/ }).first().textContent({ timeout: WAIT });
  assert.match(said, /enabled/);
  await rest(daemon.base, "POST", "/api/v1/buses/sim0/devices/1/disable");
});
