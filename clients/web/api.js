// The HTTP API as the web client uses it: JSON in and out, problem+json errors turned into ApiError, the bearer
// token (kept in sessionStorage) on every request, and a connection state the page shows.

const TOKEN_KEY = "tessera.token";

export class ApiError extends Error {
  // status: the HTTP status (0 when the server could not be reached); problem: the problem+json body, if any;
  // retryAfterMs: how long the server asked to wait before trying again (Retry-After of a 429 or 503), or null.
  constructor(status, problem, fallback, retryAfterMs = null) {
    const title = problem?.title || fallback || (status ? `HTTP ${status}` : "Network error");
    const detail = problem?.detail || "";
    super(detail ? `${title}: ${detail}` : title);
    this.status = status;
    this.title = title;
    this.detail = detail;
    this.pointer = problem?.pointer ?? null;
    // Every error of a refused document, [{pointer, detail}], when it has more than one (the first is detail).
    this.errors = Array.isArray(problem?.errors) ? problem.errors.filter((e) => typeof e?.detail === "string") : [];
    this.problem = problem || null;
    this.retryAfterMs = retryAfterMs;
  }
}

// A Retry-After header (RFC 9110 10.2.3: seconds, or an HTTP date) in milliseconds from now, at most ten minutes;
// null when absent or unreadable.
export function retryAfterMs(value, now = Date.now()) {
  if (value == null || value === "") return null;
  let ms;
  if (/^\s*\d+\s*$/.test(value)) ms = Number(value) * 1000;
  else {
    const at = Date.parse(value);
    if (Number.isNaN(at)) return null;
    ms = at - now;
  }
  return Math.min(Math.max(ms, 0), 600000);
}

export function getToken() {
  try {
    return sessionStorage.getItem(TOKEN_KEY) || "";
  } catch {
    return "";
  }
}

export function setToken(token) {
  try {
    if (token) sessionStorage.setItem(TOKEN_KEY, token);
    else sessionStorage.removeItem(TOKEN_KEY);
  } catch {
    // storage disabled: the token lives until the page is closed
  }
}

// Listeners of connection changes: state is "online", "offline", "unauthorized" or "error".
const listeners = new Set();
let connection = "connecting";
export function onConnection(fn) {
  listeners.add(fn);
  fn(connection);
  return () => listeners.delete(fn);
}
function setConnection(state) {
  if (state === connection) return;
  connection = state;
  for (const fn of listeners) fn(state);
}

function headers(extra) {
  const h = new Headers(extra || {});
  const token = getToken();
  if (token) h.set("Authorization", `Bearer ${token}`);
  return h;
}

async function problemOf(res) {
  const type = res.headers.get("Content-Type") || "";
  try {
    if (type.includes("json")) return await res.json();
    const text = await res.text();
    return text ? { detail: text.slice(0, 300) } : null;
  } catch {
    return null;
  }
}

// Sends a request; returns the Response of a 2xx answer, throws ApiError otherwise.
export async function request(method, path, { body, json, headers: extra, signal } = {}) {
  const h = headers(extra);
  let payload = body;
  if (json !== undefined) {
    h.set("Content-Type", "application/json");
    payload = JSON.stringify(json);
  }
  let res;
  try {
    res = await fetch(path, { method, headers: h, body: payload, signal, cache: "no-store" });
  } catch (e) {
    if (e.name === "AbortError") throw e;
    setConnection("offline");
    throw new ApiError(0, null, "Cannot reach the server");
  }
  if (res.status === 401) {
    setConnection("unauthorized");
  } else if (res.status >= 500) {
    setConnection("error");
  } else {
    setConnection("online");
  }
  if (!res.ok) {
    const wait = res.status === 429 || res.status === 503 ? retryAfterMs(res.headers.get("Retry-After")) : null;
    throw new ApiError(res.status, await problemOf(res), undefined, wait);
  }
  return res;
}

export async function getJson(path, opts) {
  const res = await request("GET", path, opts);
  return res.json();
}

export async function sendJson(method, path, json) {
  const res = await request(method, path, json === undefined ? {} : { json });
  if (res.status === 204) return null;
  const type = res.headers.get("Content-Type") || "";
  return type.includes("json") ? res.json() : null;
}

export async function getBlob(path, opts) {
  const res = await request("GET", path, opts);
  return res.blob();
}

// The job endpoints.
export const api = {
  listJobs: (limit = 200) => getJson(`/v1/jobs?limit=${limit}`),
  getJob: (id) => getJson(`/v1/jobs/${encodeURIComponent(id)}`),
  submitJson: (doc) => sendJson("POST", "/v1/jobs", doc),
  // multipart/form-data: a part "job" (the JSON) plus the files; the browser sets the boundary.
  submitMultipart: async (doc, files) => {
    const form = new FormData();
    form.append("job", new Blob([JSON.stringify(doc)], { type: "application/json" }), "job.json");
    for (const f of files) form.append("file", f, f.name);
    const res = await request("POST", "/v1/jobs", { body: form });
    return res.json();
  },
  // The document the job was accepted with.
  document: (id) => getJson(`/v1/jobs/${encodeURIComponent(id)}/document`),
  // The job's log (text): loading, warnings, passes, how it ended.
  jobLog: async (id) => (await request("GET", `/v1/jobs/${encodeURIComponent(id)}/log`)).text(),
  action: (id, action) => sendJson("POST", `/v1/jobs/${encodeURIComponent(id)}/${action}`),
  setPriority: (id, priority) =>
    sendJson("PATCH", `/v1/jobs/${encodeURIComponent(id)}`, { priority }),
  remove: (id) => sendJson("DELETE", `/v1/jobs/${encodeURIComponent(id)}`),
  materials: () => getJson("/v1/materials"),
  // The example jobs of proto/examples, {"<file name>": <job document>}: a file of the web client, like app.js.
  examples: () => getJson("examples.json"),
  schema: (name) => getJson(`/v1/schemas/${encodeURIComponent(name)}`),
  eventsUrl: (id) => {
    const token = getToken();
    const q = token ? `?access_token=${encodeURIComponent(token)}` : "";
    return `/v1/jobs/${encodeURIComponent(id)}/events${q}`;
  },
};

// Which actions a job's state allows: the daemon says, in the status's "actions" (its state table), so the buttons
// never disagree with what it accepts. "result": result images exist (its links name them: a succeeded job's, or
// the partial image of one cancelled after a pass); "result_png", "result_exr": that one exists.
export const TERMINAL = new Set(["succeeded", "failed", "cancelled"]);
export function allowed(job, action) {
  if (action === "result") return Boolean(job.links?.result_png || job.links?.result_exr);
  if (action === "result_png" || action === "result_exr") return Boolean(job.links?.[action]);
  return Array.isArray(job.actions) && job.actions.includes(action);
}
