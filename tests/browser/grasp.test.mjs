// Grasping from a hand's card: with a simulated object before the thumb and
// none before the index, Grasp closes both (to the hand's pose `closed`);
// the thumb's row shows contact near the object and the hold current, the
// index's `no_contact`, updated live; Release opens both and the limits are
// restored; a refused grasp says why. The hand's card stays clean at
// 800, 1400 and 1920 px with the fingers' table shown.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startDaemon, launchBrowser, openDashboard, rest, waitFsm, WAIT } from "./harness.mjs";

const HAND = `[[hand]]\nname = "right"\njoints = [{ bus = "sim0", ids = "1-2", names = ["thumb", "index"] }]\n`;
let daemon, browser, page, errors;

before(async () => {
  daemon = await startDaemon(["--sim", "2", "--sim-object", "1=12:0.05"], HAND);
  await rest(daemon.base, "PUT", "/api/v1/hands/right/poses/closed", { positions_deg: { thumb: 40, index: 20 } });
  browser = await launchBrowser();
  ({ page, errors } = await openDashboard(browser, daemon.base));
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

/** The text of finger `joint`'s cell `field` in the hand's grasp table. */
const cell = (joint, field) =>
  page.locator(`[data-testid="grasp-finger-right-${joint}"] td[data-field="${field}"]`).textContent({ timeout: WAIT });

/** Waits until finger `joint`'s row says `state`. */
const fingerState = (joint, state) => page.waitForFunction(([joint, state]) =>
  document.querySelector(`[data-testid="grasp-finger-right-${joint}"]`)?.dataset.state === state, [joint, state], { timeout: WAIT });

test("a grasp that cannot start says why", async () => {
  // Nothing is enabled yet: the daemon refuses, the card shows its detail.
  await page.locator('[data-testid="grasp-right"]').click({ timeout: WAIT });
  const shown = await page.locator("#messages .error").first().textContent({ timeout: WAIT });
  assert.match(shown, /thumb|index|enabled/i, shown);
  assert.equal(await page.locator('[data-testid="grasp-state-right"]').textContent(), "");
});

test("Grasp closes on the object and reports each finger live; Release lets go", async () => {
  await rest(daemon.base, "POST", "/api/v1/buses/sim0/control/enable", { ids: [1, 2] });
  await waitFsm(page, 1, "run");
  await waitFsm(page, 2, "run");
  assert.equal(await page.locator('[data-testid="grasp-speed-right"]').inputValue(), "30");
  assert.equal(await page.locator('[data-testid="grasp-hold-right"]').inputValue(), "0.2");
  await page.locator('[data-testid="grasp-right"]').click();
  // While it closes, the rows are there and say so.
  await page.locator('[data-testid="grasp-finger-right-index"]').waitFor({ timeout: WAIT });
  await fingerState("thumb", "holding");
  await fingerState("index", "no_contact");
  assert.match(await page.locator('[data-testid="grasp-state-right"]').textContent(), /^Grasp \d+: running$/);
  assert.equal(await cell("thumb", "contact"), "yes");
  const at = Number(await cell("thumb", "contact_deg"));
  assert.ok(at > 10 && at < 14, `contact at ${at}°`);
  assert.equal(await cell("index", "contact"), "no");
  assert.equal(await cell("index", "contact_deg"), "–");
  // The thumb's current comes up to the hold current (updated live).
  await page.waitForFunction(() => {
    const q = Number(document.querySelector('[data-testid="grasp-finger-right-thumb"] td[data-field="q_current_a"]')?.textContent);
    return Math.abs(q - 0.2) <= 0.02;
  }, null, { timeout: WAIT });

  await page.locator('[data-testid="grasp-release-right"]').click();
  await fingerState("thumb", "released");
  await fingerState("index", "released");
  assert.match(await page.locator('[data-testid="grasp-state-right"]').textContent(), /^Grasp \d+: done$/);
  const id = Number((await page.locator('[data-testid="grasp-state-right"]').textContent()).match(/\d+/)[0]);
  const view = await rest(daemon.base, "GET", `/api/v1/grasps/${id}`);
  assert.ok(view.fingers.every((f) => f.state === "released" && f.current_limit_restored), JSON.stringify(view));
  assert.deepEqual(errors, []);
});

test("Stop holds the fingers where they are", async () => {
  await page.locator('[data-testid="grasp-speed-right"]').fill("10");
  await page.locator('[data-testid="grasp-right"]').click();
  await fingerState("index", "closing");
  await page.locator('[data-testid="grasp-stop-right"]').click();
  await fingerState("thumb", "stopped");
  await fingerState("index", "stopped");
  const grasp = await rest(daemon.base, "GET", "/api/v1/grasps/2");
  assert.equal(grasp.state, "done");
  assert.deepEqual(errors, []);
});

for (const viewport of [{ width: 800, height: 900 }, { width: 1400, height: 900 }, { width: 1920, height: 1080 }]) {
  test(`the hand's grasp controls fit at ${viewport.width} px`, async () => {
    const { page: p, errors: errs } = await openDashboard(browser, daemon.base, viewport);
    try {
      // The fingers' table shows once a grasp runs.
      await p.locator('[data-testid="grasp-right"]').click({ timeout: WAIT });
      await p.locator('[data-testid="grasp-finger-right-thumb"]').waitFor({ timeout: WAIT });
      const m = await p.evaluate(() => {
        const box = (e) => e.getBoundingClientRect();
        const card = box(document.querySelector('[data-testid="hand-right"]'));
        const outside = [];
        for (const e of document.querySelectorAll('[data-testid="hand-right"] button, [data-testid="hand-right"] input, [data-testid="hand-right"] th')) {
          const b = box(e);
          if (b.left < card.left - 0.5 || b.right > card.right + 0.5) outside.push(e.dataset.testid || e.textContent);
        }
        return { outside, pageOverflow: document.documentElement.scrollWidth - innerWidth };
      });
      assert.deepEqual(m.outside, [], `outside the hand's card at ${viewport.width} px`);
      assert.ok(m.pageOverflow <= 0, `the page scrolls sideways by ${m.pageOverflow} px`);
      const id = Number((await p.locator('[data-testid="grasp-state-right"]').textContent()).match(/\d+/)[0]);
      await rest(daemon.base, "POST", `/api/v1/grasps/${id}/stop`);
      assert.deepEqual(errs, []);
    } finally {
      await p.close();
    }
  });
}
