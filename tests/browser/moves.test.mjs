// Smooth moves from the joint panel against `jointd --sim 4`: the move is
// the daemon's (POST /api/v1/moves), followed until it ends, and Stop ends
// it (DELETE). A joint the user has not enabled is never enabled by the
// page: the daemon's refusal is shown.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startDaemon, launchBrowser, openDashboard, rest, selectJoint, waitFsm, waitAngle, WAIT } from "./harness.mjs";

let daemon, browser, page, errors;

before(async () => {
  daemon = await startDaemon(["--sim", "4"]);
  browser = await launchBrowser();
  ({ page, errors } = await openDashboard(browser, daemon.base));
  await selectJoint(page, 2);
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

const moveState = () => page.locator('[data-testid="move-state"]');

async function smoothMove(deg, ms) {
  await page.locator('[data-testid="target-number"]').fill(String(deg));
  await page.locator('[data-testid="move-ms"]').fill(String(ms));
  await page.locator('[data-testid="move"]').click();
}

test("a smooth move of a joint not enabled is refused, shown, and enables nothing", async () => {
  await smoothMove(30, 500);
  const shown = page.locator("#messages .error").first();
  await shown.waitFor({ timeout: WAIT });
  const said = await shown.textContent();
  const answer = await fetch(`${daemon.base}/api/v1/moves`, {
    method: "POST", headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ joints: [{ bus: "sim0", id: 2, position_deg: 30 }], duration_ms: 500 }),
  });
  const problem = await answer.json();
  assert.equal(answer.status, 409, JSON.stringify(problem));
  assert.equal(said, problem.detail, "the problem's detail is shown as the daemon gave it");
  const dev = await rest(daemon.base, "GET", "/api/v1/buses/sim0/devices/2");
  assert.notEqual(dev.status.state, "run", "the page enabled the joint");
  assert.equal(await moveState().textContent(), "", "no move shown");
});

test("a smooth move to the target is followed until done and arrives", async () => {
  assert.equal(await page.locator('[data-testid="move"]').textContent(), "Smooth move");
  await page.locator('[data-testid="enable"]').click();
  await waitFsm(page, 2, "run");
  await smoothMove(40, 1500);
  await page.waitForFunction(() => document.querySelector('[data-testid="move-state"]')?.dataset.state === "running", null, { timeout: WAIT });
  assert.equal(await page.locator('[data-testid="move-stop"]').isDisabled(), false, "Stop is offered while it runs");
  await page.waitForFunction(() => document.querySelector('[data-testid="move-state"]')?.dataset.state === "done", null, { timeout: WAIT });
  const text = await moveState().textContent();
  const id = Number(text.match(/^Move (\d+): done$/)?.[1]);
  assert.ok(id > 0, `state line: ${text}`);
  assert.equal((await rest(daemon.base, "GET", `/api/v1/moves/${id}`)).state, "done");
  await waitAngle(page, 2, 40);
  assert.equal(await page.locator('[data-testid="move-stop"]').isDisabled(), true, "no Stop once done");
});

test("Stop ends a running move and the joint holds short of the target", async () => {
  await smoothMove(-40, 8000);
  await page.waitForFunction(() => /running [1-9]\d* %/.test(document.querySelector('[data-testid="move-state"]')?.textContent || ""), null, { timeout: WAIT });
  const id = Number((await moveState().textContent()).match(/^Move (\d+)/)[1]);
  await page.locator('[data-testid="move-stop"]').click();
  await page.waitForFunction(() => document.querySelector('[data-testid="move-state"]')?.dataset.state === "stopped", null, { timeout: WAIT });
  const mv = await rest(daemon.base, "GET", `/api/v1/moves/${id}`);
  assert.equal(mv.state, "stopped");
  assert.ok(mv.progress < 1, `progress ${mv.progress}`);
  const dev = await rest(daemon.base, "GET", "/api/v1/buses/sim0/devices/2");
  assert.ok(dev.target.position_deg > -39, `held at ${dev.target.position_deg}°, not the move's end`);
  assert.deepEqual(errors, []);
});
