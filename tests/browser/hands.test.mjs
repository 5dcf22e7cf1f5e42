// A hand (`[[hand]]` in the config) in the dashboard: its joints and saved
// poses; Save current keeps where it is (PUT from_current), a pose's button
// goes there (POST …/go, followed until done), × deletes it (DELETE).

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startDaemon, launchBrowser, openDashboard, rest, selectJoint, waitFsm, waitAngle, WAIT } from "./harness.mjs";

const HAND = `[[hand]]\nname = "left"\njoints = [{ bus = "sim0", ids = "1-2", names = ["thumb", "index"] }]\n`;
let daemon, browser, page, errors;

before(async () => {
  daemon = await startDaemon(["--sim", "4"], HAND);
  browser = await launchBrowser();
  ({ page, errors } = await openDashboard(browser, daemon.base));
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

const target = (id, deg) => rest(daemon.base, "PUT", `/api/v1/buses/sim0/devices/${id}/target`, { position_deg: deg, speed_dps: 200 });

test("the hand is shown with its joints and no poses yet", async () => {
  const hand = page.locator('[data-testid="hand-left"]');
  await hand.waitFor({ timeout: WAIT });
  const text = await hand.textContent();
  assert.match(text, /thumb \(sim0\/1\), index \(sim0\/2\)/);
  assert.match(text, /no saved poses/);
});

test("a pose saved from where the hand is, gone back to, then deleted", async () => {
  // The user enables both joints in their panels.
  for (const id of [1, 2]) {
    await selectJoint(page, id);
    await page.locator('[data-testid="enable"]').click();
    await waitFsm(page, id, "run");
  }
  await target(1, 20);
  await target(2, -10);
  await waitAngle(page, 1, 20);
  await waitAngle(page, 2, -10);

  await page.locator('[data-testid="pose-name-left"]').fill("grip");
  await page.locator('[data-testid="pose-save-left"]').click();
  const go = page.locator('[data-testid="pose-left-grip"]');
  await go.waitFor({ timeout: WAIT });
  const saved = await rest(daemon.base, "GET", "/api/v1/hands/left/poses/grip");
  assert.ok(Math.abs(saved.positions_deg.thumb - 20) < 1 && Math.abs(saved.positions_deg.index + 10) < 1, JSON.stringify(saved));

  await target(1, 0);
  await target(2, 0);
  await waitAngle(page, 1, 0);
  await waitAngle(page, 2, 0);
  await page.locator('[data-testid="move-ms"]').fill("600");
  await go.click();
  await page.waitForFunction(() => document.querySelector('[data-testid="hand-move-state-left"]')?.dataset.state === "done", null, { timeout: WAIT });
  assert.match(await page.locator('[data-testid="hand-move-state-left"]').textContent(), /^Move \d+: done$/);
  await waitAngle(page, 1, 20);
  await waitAngle(page, 2, -10);

  page.once("dialog", (d) => d.accept());
  await page.locator('[data-testid="pose-delete-left-grip"]').click();
  await go.waitFor({ state: "detached", timeout: WAIT });
  const gone = await fetch(`${daemon.base}/api/v1/hands/left/poses/grip`);
  assert.equal(gone.status, 404);
  assert.deepEqual(errors, []);
});

test("a pose that cannot be saved says why", async () => {
  // A name the daemon refuses: its detail is shown, nothing is saved.
  await page.locator('[data-testid="pose-name-left"]').fill("x".repeat(300));
  await page.locator('[data-testid="pose-save-left"]').click();
  const shown = await page.locator("#messages .error").first().textContent({ timeout: WAIT });
  assert.match(shown, /^pose name `x+`: 1\.\.=64 letters, digits, `_` or `-`$/);
  const hands = await rest(daemon.base, "GET", "/api/v1/hands");
  assert.deepEqual(hands.hands[0].poses, []);
});

test("a program streaming to the hand is shown on its card until its stream ends", async () => {
  const line = page.locator('[data-testid="hand-streams-left"]');
  assert.equal(await line.isHidden(), true);
  // A teleop client (here opened from the page's own origin) streams to
  // the index joint under the name it gave; the joints run from the test above.
  await page.evaluate(async () => {
    const ws = new WebSocket(`${location.origin.replace("http", "ws")}/api/v1/ws?client=lerobot-test`);
    window.__teleop = ws;
    await new Promise((r) => ws.addEventListener("open", r));
    ws.send(JSON.stringify({ type: "setpoints", targets: [{ hand: "left", joint: "index", position_deg: 3 }] }));
  });
  // One setpoint, then none: the card reads the streams every second and
  // adds how long the stream has been idle once that passes a second.
  await page.waitForFunction(() => /Driven by lerobot-test \(WebSocket client \d+(, idle \d+ s)?\): index$/.test(
    document.querySelector('[data-testid="hand-streams-left"]')?.textContent || ""), null, { timeout: WAIT });
  assert.equal(await line.isVisible(), true);
  await page.evaluate(() => window.__teleop.close());
  await line.waitFor({ state: "hidden", timeout: WAIT });
  assert.deepEqual(errors, []);
});
