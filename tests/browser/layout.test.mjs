// The dashboard's layout at a 1400×900 and a 1920×1080 screen and a narrow
// 800 px window, with no joint selected and with one: no table column is
// cut (each header lies whole inside the window and inside the box that
// holds its table), the device table does not overflow, and the page uses
// its width (no half-empty screen).

import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { startDaemon, launchBrowser, openDashboard, selectJoint, waitConfig, WAIT } from "./harness.mjs";

const VIEWPORTS = [{ width: 1400, height: 900 }, { width: 1920, height: 1080 }, { width: 800, height: 900 }];
let daemon, browser;

before(async () => {
  daemon = await startDaemon(["--sim", "16"]);
  browser = await launchBrowser();
});

after(async () => {
  await browser?.close();
  await daemon?.stop();
});

/** What the test asserts, measured in the page. */
function measure() {
  const box = (e) => e.getBoundingClientRect();
  const cut = [];
  for (const th of document.querySelectorAll("table th")) {
    if (!th.offsetParent) continue;           // in a hidden part
    const b = box(th);
    // The table's holder: a scrolling box, else its section.
    const holder = box(th.closest(".scroll, section"));
    const right = Math.min(innerWidth, holder.right), left = Math.max(0, holder.left);
    if (b.right > right + 0.5 || b.left < left - 0.5) {
      cut.push(`${th.closest("table").id}: "${th.textContent}" spans ${Math.round(b.left)}..${Math.round(b.right)}, its box ${Math.round(left)}..${Math.round(right)}`);
    }
  }
  const section = document.querySelector("#devices-section");
  const panel = document.querySelector("#panel");
  const used = [document.querySelector("#devices"), panel.hidden ? null : panel].filter(Boolean).map(box);
  return {
    cut,
    devicesOverflow: section.scrollWidth - section.clientWidth,
    pageOverflow: document.documentElement.scrollWidth - innerWidth,
    usedLeft: Math.min(...used.map((b) => b.left)),
    usedRight: Math.max(...used.map((b) => b.right)),
  };
}

for (const viewport of VIEWPORTS) {
  test(`at ${viewport.width}×${viewport.height} no column is cut and the width is used`, async () => {
    const { page, errors } = await openDashboard(browser, daemon.base, viewport);
    try {
      await page.waitForFunction(() => document.querySelectorAll('[data-testid^="device-row-sim0-"]').length === 16, null, { timeout: WAIT });
      for (const selected of [false, true]) {
        if (selected) {
          await selectJoint(page, 1);
          await waitConfig(page, daemon.base);
        }
        const m = await page.evaluate(measure);
        const when = `${viewport.width} px, ${selected ? "joint 1 selected" : "no joint selected"}`;
        assert.deepEqual(m.cut, [], `columns cut at ${when}`);
        assert.ok(m.devicesOverflow <= 0, `the device table overflows its section by ${m.devicesOverflow} px at ${when}`);
        assert.ok(m.pageOverflow <= 0, `the page scrolls sideways by ${m.pageOverflow} px at ${when}`);
        // The device table (and the panel beside it) span the window but
        // for the page's margins.
        const spread = m.usedRight - m.usedLeft;
        assert.ok(spread >= viewport.width - 60, `the content spans ${Math.round(spread)} of ${viewport.width} px at ${when}`);
      }
      assert.deepEqual(errors, []);
    } finally {
      await page.close();
    }
  });
}
