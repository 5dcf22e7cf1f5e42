// What this dashboard's token may do (GET /api/v1/caller): a control that
// needs more says so and is greyed out (the daemon refuses it anyway, 403).
// Controls name what they need with data-needs="operate" | "admin"; ones
// added later (a hand's grasp buttons, its poses) are seen as they come.

import { api } from "./api.js";

const RANK = { read: 0, operate: 1, admin: 2 };
const caller = { name: "", scope: "admin" };

/** Whether the token reaches `needs`. */
export function may(needs) {
  return (RANK[caller.scope] ?? 0) >= (RANK[needs] ?? 2);
}

function mark(node) {
  const ok = may(node.dataset.needs);
  node.classList.toggle("out-of-scope", !ok);
  node.setAttribute("aria-disabled", String(!ok));
  if (node.dataset.title === undefined) node.dataset.title = node.title || "";
  node.title = ok ? node.dataset.title
    : `${node.dataset.title ? node.dataset.title + " — " : ""}needs a token of scope ${node.dataset.needs} (${caller.name} is ${caller.scope})`;
  if (!ok) node.tabIndex = -1;
  else node.removeAttribute("tabindex");
}

function markAll(root) {
  if (root.matches?.("[data-needs]")) mark(root);
  root.querySelectorAll?.("[data-needs]").forEach(mark);
}

/** Asks the daemon who this token is, then marks every control. A daemon
 *  that cannot say (an older one, or the token refused): look only. */
export async function loadScope() {
  try {
    const c = await api("GET", "caller");
    caller.name = c.name;
    caller.scope = c.scope;
  } catch {
    caller.name = "this token";
    caller.scope = "read";
  }
  document.body.dataset.scope = caller.scope;
  markAll(document.body);
}

new MutationObserver((records) => {
  for (const r of records) for (const n of r.addedNodes) if (n.nodeType === 1) markAll(n);
}).observe(document.body, { childList: true, subtree: true });
