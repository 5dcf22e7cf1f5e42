// The dashboard with a scoped token: what the token cannot do is greyed out
// (and cannot be clicked), what it can is not; the e-stop never is. A read
// token's page leaves the joints as they were; the same page with an
// operate token enables one; neither may touch configuration.

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { WAIT, launchBrowser, selectJoint, startDaemon } from "./harness.mjs";

const TOKENS = { watch: "watch-secret-1", policy: "policy-secret-2" };

let daemon, browser, base;

before(async () => {
  process.env.JOINTD_TEST_TOKEN_WATCH = TOKENS.watch;
  process.env.JOINTD_TEST_TOKEN_POLICY = TOKENS.policy;
  daemon = await startDaemon(["--sim", "2"],
    '[[tokens]]\nname = "watch"\nscope = "read"\nenv = "JOINTD_TEST_TOKEN_WATCH"\n\n' +
    '[[tokens]]\nname = "policy"\nscope = "operate"\nenv = "JOINTD_TEST_TOKEN_POLICY"\n',
    TOKENS.watch);
  base = daemon.base;
  browser = await launchBrowser();
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

/** A page of the dashboard holding `token`, once it knows the token's scope. */
async function pageWith(token, scope) {
  const page = await browser.newPage({ viewport: { width: 1400, height: 900 } });
  page.on("pageerror", (e) => console.error("page error:", e.message));
  await page.addInitScript((t) => localStorage.setItem("jointd-token", t), token);
  await page.goto(base);
  await page.waitForFunction((s) => document.body.dataset.scope === s, scope, { timeout: WAIT });
  await selectJoint(page, 1);
  return page;
}

const greyed = (page, selector) => page.locator(selector).evaluate(
  (n) => n.classList.contains("out-of-scope") && n.getAttribute("aria-disabled") === "true");

async function state(id) {
  const r = await fetch(`${base}/api/v1/buses/sim0/devices/${id}`,
    { headers: { Authorization: `Bearer ${TOKENS.watch}` } });
  assert.equal(r.status, 200);
  return (await r.json()).status.state;
}

test("a read token's dashboard greys out every command but the e-stop", async () => {
  const page = await pageWith(TOKENS.watch, "read");
  for (const sel of ["#record", "#enable", "#target-slider", "#move", "#rezero", "#config-apply", "#change-id"]) {
    assert.equal(await greyed(page, sel), true, `${sel} greyed for a read token`);
  }
  assert.equal(await greyed(page, "#estop"), false, "the e-stop is every token's");
  const title = await page.locator("#enable").getAttribute("title");
  assert.match(title, /needs a token of scope operate \(watch is read\)/);
  // Greyed is not clickable: the joint stays as it was.
  await assert.rejects(page.locator("#enable").click({ timeout: 1000 }));
  assert.notEqual(await state(1), "run");
  await page.close();
});

test("an operate token's dashboard moves joints but does not configure them", async () => {
  const page = await pageWith(TOKENS.policy, "operate");
  for (const sel of ["#record", "#enable", "#target-slider", "#move"]) {
    assert.equal(await greyed(page, sel), false, `${sel} open to an operate token`);
  }
  for (const sel of ["#rezero", "#config-apply", "#config-persist", "#change-id", "#cal-set"]) {
    assert.equal(await greyed(page, sel), true, `${sel} needs admin`);
  }
  await page.locator("#enable").click({ timeout: WAIT });
  const deadline = Date.now() + WAIT;
  while ((await state(1)) !== "run") {
    assert.ok(Date.now() < deadline, "joint 1 never ran");
    await new Promise((r) => setTimeout(r, 50));
  }
  await page.close();
});
