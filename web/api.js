// Talking to the daemon's REST API (openapi/openapi.json) and telling the
// user how it went: every failure is shown with the problem's detail.

export const API = "/api/v1";
export const $ = (sel) => document.querySelector(sel);

/** The bearer token, when the daemon asks for one (kept in localStorage). */
export const session = { token: localStorage.getItem("jointd-token") || "" };

/** Called when the API answers 401 (app.js asks for the token). */
let onUnauthorized = () => {};
export function whenUnauthorized(fn) { onUnauthorized = fn; }

// ---------------------------------------------------------------- messages

export function say(text, kind = "error") {
  const div = document.createElement("div");
  div.className = kind;
  div.textContent = text;
  $("#messages").prepend(div);
  setTimeout(() => div.remove(), kind === "error" ? 8000 : 3000);
  while ($("#messages").children.length > 4) $("#messages").lastChild.remove();
}

/** A problem-details body (or anything) as one sentence. */
export function describe(body, status) {
  if (body && typeof body === "object") {
    let text = body.detail || body.title || JSON.stringify(body);
    if (body.allowed) text += ` (allowed ${body.allowed.min}..${body.allowed.max} ${body.allowed.unit})`;
    if (body.partial) text += ` — outcome so far: ${JSON.stringify(body.partial)}`;
    return text;
  }
  return `HTTP ${status}`;
}

// ---------------------------------------------------------------- REST

export function authHeaders() {
  return session.token ? { "Authorization": `Bearer ${session.token}` } : {};
}

export async function api(method, path, body) {
  const headers = { "Accept": "application/json", ...authHeaders() };
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const res = await fetch(path.startsWith("/") ? path : `${API}/${path}`, {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body),
  });
  const text = await res.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch { data = text; }
  if (res.status === 401) onUnauthorized();
  if (!res.ok) throw new Error(describe(data, res.status));
  return data;
}

/** Runs a user action; failures are shown in words. */
export async function act(label, fn) {
  try {
    const result = await fn();
    if (label) say(label, "info");
    return result;
  } catch (e) {
    say(`${label ? label.replace(/\.$/, "") + " failed: " : ""}${e.message}`);
    return null;
  }
}

/** Reads `path` every `ms` and hands each answer to `show` until `ended`
 *  says so (or a read fails: shown, and the watch ends). */
export async function watch(path, show, ended, ms = 200) {
  for (;;) {
    let view;
    try { view = await api("GET", path); } catch (e) { say(`Reading ${path} failed: ${e.message}`); return null; }
    show(view);
    if (ended(view)) return view;
    await new Promise((r) => setTimeout(r, ms));
  }
}

/** The path of joint `{bus, id}` under the API. */
export const devicePath = ({ bus, id }, rest = "") => `buses/${encodeURIComponent(bus)}/devices/${id}${rest}`;

/** A small element: `el("button", {textContent: "Go"}, child…)`. */
export function el(tag, props = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(props)) {
    if (k === "testid") node.dataset.testid = v;
    else if (k === "needs") node.dataset.needs = v;
    else node[k] = v;
  }
  node.append(...children);
  return node;
}
