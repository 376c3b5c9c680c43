// The web client's page: the submit form, the queue, the job view. State lives in the daemon; this page polls the
// job list and follows the selected job over Server-Sent Events (polling when the events endpoint is missing).
import { api, allowed, ApiError, getBlob, getToken, onConnection, setToken, TERMINAL } from "./api.js";
import { CLIENT_EXAMPLES, examplesFrom } from "./examples.js";
import { cryptomatteOfPass, decodeExr, ExrError } from "./exr.js";
import { FrameStrip, frameState, frameUrl } from "./frames.js";
import { MATERIAL_PRESETS, materialForm, NOT_ON_PREVIEW_STAGE } from "./materials.js";
import { ImageViewer } from "./viewer.js";

const $ = (sel) => document.querySelector(sel);
const STATES = ["queued", "running", "paused", "succeeded", "failed", "cancelled"];
const QUEUE_POLL_MS = 1500;
const JOB_POLL_MS = 1000;

// ---------------------------------------------------------------------------------------------------------------
// Small helpers

function fmtSeconds(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  if (s < 1) return `${(s * 1000).toFixed(0)} ms`;
  if (s < 60) return `${s.toFixed(1)} s`;
  const m = Math.floor(s / 60);
  if (m < 60) return `${m} min ${Math.round(s - 60 * m)} s`;
  return `${Math.floor(m / 60)} h ${m % 60} min`;
}
function fmtRate(x) {
  if (!x) return "–";
  const units = [
    [1e9, "G"],
    [1e6, "M"],
    [1e3, "k"],
  ];
  for (const [k, u] of units) if (x >= k) return `${(x / k).toFixed(2)} ${u}`;
  return x.toFixed(0);
}
function fmtTime(iso) {
  if (!iso) return "–";
  const d = new Date(iso);
  const today = new Date();
  const time = d.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit", second: "2-digit" });
  return d.toDateString() === today.toDateString() ? time : `${d.toLocaleDateString()} ${time}`;
}
const shortId = (id) => id.slice(0, 8);
// A job as people call it: its name and the 8 digits of its id that the command line takes.
const jobLabel = (job) => (job.name ? `${job.name} (${shortId(job.id)})` : shortId(job.id));

// "37/1024 spp", or for a job sampled adaptively (render.adaptive_threshold), whose samples_done is the mean over its
// pixels and samples_total the most any pixel gets: "mean 37 of at most 1024 spp".
const adaptive = (job) => job.render?.adaptive_threshold > 0;
function samplesText(job, unit = "spp") {
  const p = job.progress || {};
  return adaptive(job)
    ? `mean ${p.samples_done ?? 0} of at most ${p.samples_total ?? 0} ${unit}`
    : `${p.samples_done ?? 0}/${p.samples_total ?? 0} ${unit}`;
}

function progressText(job) {
  const p = job.progress || {};
  const parts = [samplesText(job)];
  if (job.state === "running" && p.eta_s !== null && p.eta_s !== undefined) parts.push(`ETA ${fmtSeconds(p.eta_s)}`);
  if (job.state === "queued" && job.queue_position) parts.push(`#${job.queue_position} in queue`);
  if (job.stop_reason && job.stop_reason !== "samples") parts.push(`stopped by ${job.stop_reason.replace("_", " ")}`);
  return parts.join(" · ");
}

function setProgress(bar, job) {
  const f = Math.max(0, Math.min(1, job.progress?.fraction ?? 0));
  bar.style.setProperty("--fraction", f);
  bar.dataset.state = job.state;
  bar.setAttribute("aria-valuenow", String(Math.round(f * 100)));
  bar.setAttribute("aria-valuetext", `${Math.round(f * 100)} percent, ${progressText(job)}`);
}

// ---------------------------------------------------------------------------------------------------------------
// Errors: problem+json title and detail, in one dismissible banner under the top bar. It shows the latest error
// only (an older one is replaced, not stacked), and goes when dismissed, after 20 s, or when a submit succeeds.

function clearErrors() {
  $("#toasts").replaceChildren();
}

function showError(err, context) {
  if (err?.name === "AbortError") return;
  const toasts = $("#toasts");
  const toast = document.createElement("div");
  toast.className = "toast";
  toast.setAttribute("role", "alert");
  const title = document.createElement("strong");
  const detail = document.createElement("span");
  let list = null;
  if (err instanceof ApiError) {
    title.textContent = (context ? `${context}: ` : "") + err.title + (err.status ? ` (${err.status})` : "");
    detail.textContent = err.detail + (err.pointer ? ` — at ${err.pointer}` : "");
    if (err.errors.length > 1) {
      // A refused document's every error, one line each (the server sends at most 20).
      detail.textContent = `${err.errors.length} errors:`;
      list = document.createElement("ul");
      for (const e of err.errors) {
        const item = document.createElement("li");
        item.textContent = `${e.pointer || "/"}: ${e.detail}`;
        list.append(item);
      }
    }
    if (err.retryAfterMs)
      detail.textContent += ` (the server asks to retry in ${Math.ceil(err.retryAfterMs / 1000)} s)`;
    if (err.status === 401) showTokenForm(true);
  } else {
    title.textContent = context || "Error";
    detail.textContent = err?.message || String(err);
  }
  const close = document.createElement("button");
  close.type = "button";
  close.className = "ghost";
  close.textContent = "Dismiss";
  close.addEventListener("click", () => toast.remove());
  toast.append(title, detail, ...(list ? [list] : []), close);
  toasts.replaceChildren(toast);
  // On a narrow screen the bar scrolls with the page: bring the error into view.
  if (toast.getBoundingClientRect().top < 0) toast.scrollIntoView({ block: "nearest" });
  setTimeout(() => toast.remove(), 20000);
}

// Confirmations are one line in the top bar, replaced by the next one.
let noticeTimer = null;
function showNotice(text) {
  const notice = $("#notice");
  notice.textContent = text;
  clearTimeout(noticeTimer);
  noticeTimer = setTimeout(() => (notice.textContent = ""), 5000);
}

// The bar and its errors stay at the top; the sticky submit panel starts below them, whatever their height.
new ResizeObserver(([entry]) => {
  document.documentElement.style.setProperty("--top-height", `${Math.ceil(entry.borderBoxSize[0].blockSize)}px`);
}).observe($("#top"));

// ---------------------------------------------------------------------------------------------------------------
// Connection indicator and token

const CONNECTION_LABELS = {
  connecting: "Connecting…",
  online: "Connected",
  offline: "Offline — retrying",
  unauthorized: "Token needed",
  error: "Server error",
};
onConnection((state) => {
  const c = $("#connection");
  c.dataset.state = state;
  c.querySelector(".label").textContent = CONNECTION_LABELS[state] || state;
  if (state === "unauthorized") showTokenForm(true);
});

function showTokenForm(focus) {
  const form = $("#token-form");
  const wasHidden = form.hidden;
  form.hidden = false;
  if (focus && wasHidden) $("#token").focus();
}
$("#token-form").addEventListener("submit", (e) => {
  e.preventDefault();
  setToken($("#token").value.trim());
  showNotice(getToken() ? "Token saved for this browser session." : "Token cleared.");
  refreshQueue();
  loadMaterials();
  loadRenderSchema();
  if (selectedId) watcher.start(selectedId);
});
$("#token-forget").addEventListener("click", () => {
  setToken("");
  $("#token").value = "";
  showNotice("Token forgotten.");
});
if (getToken()) {
  $("#token").value = getToken();
  showTokenForm(false);
}

// ---------------------------------------------------------------------------------------------------------------
// Submit form

const tabs = [...document.querySelectorAll('[role="tab"]')];
let source = "example";
function selectTab(tab, focus) {
  for (const t of tabs) {
    const on = t === tab;
    t.setAttribute("aria-selected", String(on));
    t.tabIndex = on ? 0 : -1;
    document.getElementById(t.getAttribute("aria-controls")).hidden = !on;
  }
  source = tab.id.replace("tab-", "");
  $("#render-settings").disabled = source === "json";
  if (focus) tab.focus();
  if (source === "json" && !$("#json-doc").value.trim()) {
    $("#json-doc").value = JSON.stringify(buildFromExample(), null, 2);
  }
}
// A tab the user picks starts another submission: the name typed for the last one does not carry over to it (an
// upload would otherwise be queued under an example's name). Duplicate fills the name and picks the tab itself.
function switchTab(tab, focus) {
  if (tab.getAttribute("aria-selected") !== "true") $("#job-name").value = "";
  selectTab(tab, focus);
}
for (const t of tabs) {
  t.addEventListener("click", () => switchTab(t, false));
  t.addEventListener("keydown", (e) => {
    const i = tabs.indexOf(t);
    let next = null;
    if (e.key === "ArrowRight") next = tabs[(i + 1) % tabs.length];
    else if (e.key === "ArrowLeft") next = tabs[(i - 1 + tabs.length) % tabs.length];
    else if (e.key === "Home") next = tabs[0];
    else if (e.key === "End") next = tabs[tabs.length - 1];
    if (next) {
      e.preventDefault();
      switchTab(next, true);
    }
  });
}

// The examples: the client's own at first, the daemon's (proto/examples) ahead of them once they arrive.
const exampleSelect = $("#example");
let examples = [...CLIENT_EXAMPLES];
function listExamples() {
  const keep = exampleSelect.value;
  exampleSelect.replaceChildren(...examples.map((ex) => new Option(ex.title, ex.id)));
  if (examples.some((ex) => ex.id === keep)) exampleSelect.value = keep;
}
listExamples();
// The render settings the form chooses from a list (the contract's enums), by their control. A third element names
// the choice (value "") that sends nothing, leaving the setting to the job's kind: a material preview samples
// adaptively and denoises by default, a scene does not (README, Material jobs).
const SELECT_SETTINGS = [
  ["#integrator", "integrator"],
  ["#estimator", "estimator"],
  ["#sampler", "sampler"],
  ["#tonemap", "tonemap"],
  ["#exr-precision", "exr_precision"],
  ["#denoise", "denoise", "default"],
];
// The render settings typed as numbers that may be left empty: sent only when given, as the job's kind has a default
// for them. Their limits are the contract's (render.schema.json), set when it has been read.
const OPTIONAL_NUMBER_SETTINGS = [
  ["#time-limit", "time_limit_s"],
  ["#noise-target", "noise_target"],
  ["#adaptive-threshold", "adaptive_threshold"],
  ["#min-spp", "min_spp"],
  ["#fps", "fps"],
];
// A frame range (render.frames): its fields by their control; a range is sent when its first and last frames are
// given. Their limits are the contract's (render.schema.json, frames.properties).
const FRAME_FIELDS = [
  ["#frames-start", "start"],
  ["#frames-end", "end"],
  ["#frames-step", "step"],
];
// The render settings of a document in the form; a setting the document leaves out shows its default (the
// contract's, render.schema.json).
const RENDER_DEFAULTS = {
  width: 512, height: 512, spp: 64, max_depth: 8, integrator: "path", estimator: "mis", seed: 0,
  sampler: "sobol", exposure_ev: 0, tonemap: "clamp", exr_precision: "half",
};
// The render passes picked (render.aovs): one checkbox per pass the contract lists (render.schema.json, aovs.items),
// built when it has been read; the choice a document brings before then is kept for it.
const aovChoice = new Set();
const aovBoxes = () => [...document.querySelectorAll("#aovs input[type=checkbox]")];
function showAovChoice() {
  for (const box of aovBoxes()) box.checked = aovChoice.has(box.value);
  $("#aovs-count").textContent = aovChoice.size ? `(${aovChoice.size})` : "";
  if (aovChoice.size) $("#aovs-details").open = true;
}
function buildAovPicker(names) {
  $("#aovs-details").hidden = !names?.length;
  const labels = (names || []).map((name) => {
    const box = document.createElement("input");
    box.type = "checkbox";
    box.id = `aov-${name}`;
    box.value = name;
    box.addEventListener("change", () => {
      if (box.checked) aovChoice.add(name);
      else aovChoice.delete(name);
      $("#aovs-count").textContent = aovChoice.size ? `(${aovChoice.size})` : "";
    });
    const label = document.createElement("label");
    label.append(box, ` ${name}`);
    return label;
  });
  $("#aovs").replaceChildren($("#aovs legend"), ...labels);
  showAovChoice();
}
function fillRenderFields(render = {}, outputs = ["png", "exr"]) {
  const r = { ...RENDER_DEFAULTS, ...render };
  aovChoice.clear();
  for (const name of Array.isArray(r.aovs) ? r.aovs : []) aovChoice.add(name);
  showAovChoice();
  $("#width").value = r.width;
  $("#height").value = r.height;
  $("#spp").value = r.spp;
  for (const [sel, key] of OPTIONAL_NUMBER_SETTINGS) $(sel).value = r[key] ?? "";
  for (const [sel, key] of FRAME_FIELDS) $(sel).value = r.frames?.[key] ?? "";
  $("#max-depth").value = r.max_depth;
  $("#seed").value = r.seed;
  $("#exposure-ev").value = r.exposure_ev;
  for (const [sel, key, unset] of SELECT_SETTINGS) {
    const value = r[key] ?? (unset === undefined ? undefined : "");
    const select = $(sel);
    if (![...select.options].some((o) => o.value === value)) select.append(new Option(value, value));
    select.value = value;
  }
  $("#output-png").checked = outputs.includes("png");
  $("#output-exr").checked = outputs.includes("exr");
}
exampleSelect.addEventListener("change", () => fillRenderFields(currentExample().job.render, currentExample().job.outputs));
const currentExample = () => examples.find((e) => e.id === exampleSelect.value) || examples[0];
fillRenderFields(currentExample().job.render, currentExample().job.outputs);
// Whether the user changed a render setting (or the name) since the page loaded: the example list, which arrives a
// moment later, then leaves the form as it is.
let settingsEdited = false;
$("#render-settings").addEventListener("input", () => (settingsEdited = true));
async function loadExamples() {
  let shipped;
  try {
    shipped = examplesFrom(await api.examples());
  } catch (e) {
    showError(e, "Loading the example jobs");
    return;
  }
  examples = [...shipped, ...CLIENT_EXAMPLES];
  listExamples();
  if (settingsEdited || !shipped.length) return;
  exampleSelect.value = examples[0].id;
  fillRenderFields(currentExample().job.render, currentExample().job.outputs);
}

function renderSettings(base = {}) {
  const render = { ...base };
  const int = (sel) => {
    const input = $(sel);
    const v = Number(input.value);
    if (!Number.isInteger(v)) throw new Error(`${input.labels[0].textContent} must be a whole number`);
    return v;
  };
  const number = (sel) => {
    const input = $(sel);
    const v = Number(input.value);
    if (!Number.isFinite(v)) throw new Error(`${input.labels[0].textContent} must be a number`);
    return v;
  };
  const optional = (sel, key) => {
    if ($(sel).value.trim()) render[key] = number(sel);
    else delete render[key];
  };
  render.width = int("#width");
  render.height = int("#height");
  render.spp = int("#spp");
  render.max_depth = int("#max-depth");
  render.seed = int("#seed");
  for (const [sel, key] of OPTIONAL_NUMBER_SETTINGS) optional(sel, key);
  const frames = frameRange(render.frames, int);
  if (frames) render.frames = frames;
  else delete render.frames;
  render.exposure_ev = number("#exposure-ev");
  for (const [sel, key] of SELECT_SETTINGS) {
    if ($(sel).value) render[key] = $(sel).value;
    else delete render[key];
  }
  // The passes in the contract's order; none picked sends none.
  const boxes = aovBoxes();
  if (boxes.length) {
    const aovs = boxes.filter((b) => b.checked).map((b) => b.value);
    if (aovs.length) render.aovs = aovs;
    else delete render.aovs;
  }
  return render;
}
// The form's frame range: null when its first and last frames are empty; the document's own range keeps what the
// form has no field for (its chunk).
function frameRange(base, int) {
  const given = FRAME_FIELDS.filter(([sel]) => $(sel).value.trim());
  if (!given.length) return null;
  const range = { ...(base || {}) };
  for (const [sel, key] of FRAME_FIELDS) {
    if ($(sel).value.trim()) range[key] = int(sel);
    else delete range[key];
  }
  if (range.start === undefined || range.end === undefined) throw new Error("A frame range needs its first and last frames");
  return range;
}
// The outputs ticked: at least one.
function outputSettings() {
  const outputs = ["png", "exr"].filter((o) => $(`#output-${o}`).checked);
  if (!outputs.length) throw new Error("Tick at least one output (PNG or EXR)");
  return outputs;
}
// The job's name: the one typed in the form, else `fallback` (the example's title, the uploaded file's name; the
// daemon names a material job after its model).
function withCommon(doc, fallback) {
  const name = $("#job-name").value.trim() || fallback;
  if (name) doc.name = name;
  doc.render = renderSettings(doc.render);
  doc.outputs = outputSettings();
  const priority = Number($("#priority").value || 0);
  if (priority) doc.priority = priority;
  else delete doc.priority;
  return doc;
}
const buildFromExample = () => structuredClone(currentExample().job);

// Material models, from the daemon.
let materialModels = [];
let currentMaterialForm = null;
async function loadMaterials() {
  try {
    const catalog = await api.materials();
    materialModels = (catalog.materials || []).filter((m) => !NOT_ON_PREVIEW_STAGE.includes(m.type));
  } catch (e) {
    if (!(e instanceof ApiError && e.status === 401)) showError(e, "Loading the material models");
    return;
  }
  const select = $("#material-type");
  const previous = select.value;
  select.replaceChildren();
  for (const m of materialModels) {
    const o = document.createElement("option");
    o.value = m.type;
    o.textContent = m.title && m.title !== m.type ? `${m.title} (${m.type})` : m.type;
    select.append(o);
  }
  if (previous && materialModels.some((m) => m.type === previous)) select.value = previous;
  buildMaterialForm();
}
function buildMaterialForm() {
  const model = materialModels.find((m) => m.type === $("#material-type").value);
  $("#material-desc").textContent = model?.description || "";
  currentMaterialForm = model ? materialForm(model) : null;
  $("#material-params").replaceChildren(...(currentMaterialForm ? [currentMaterialForm.element] : []));
}
$("#material-type").addEventListener("change", () => {
  $("#material-preset").value = "";
  buildMaterialForm();
});
// Presets: the model chosen, then its parameters set on the form.
for (const preset of MATERIAL_PRESETS) {
  const o = document.createElement("option");
  o.value = o.textContent = preset.name;
  $("#material-preset").append(o);
}
$("#material-preset").addEventListener("change", () => {
  const preset = MATERIAL_PRESETS.find((p) => p.name === $("#material-preset").value);
  if (!preset || !materialModels.some((m) => m.type === preset.material.type)) return;
  $("#material-type").value = preset.material.type;
  buildMaterialForm();
  currentMaterialForm.set(preset.material);
});

// Uploads
function uploadFiles() {
  return [...$("#upload").files];
}
$("#upload").addEventListener("change", () => {
  const list = $("#upload-list");
  list.replaceChildren();
  for (const f of uploadFiles()) {
    const li = document.createElement("li");
    li.textContent = `${f.name} — ${(f.size / 1024).toFixed(1)} KiB`;
    list.append(li);
  }
});

$("#submit-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const button = $("#submit-button");
  let doc;
  let files = null;
  try {
    if (source === "example") {
      doc = withCommon(buildFromExample(), currentExample().name);
    } else if (source === "material") {
      if (!currentMaterialForm) throw new Error("No material model is loaded yet");
      doc = withCommon({ kind: "material", material: currentMaterialForm.value() });
    } else if (source === "upload") {
      files = uploadFiles();
      const main = files.find((f) => /\.glb$/i.test(f.name)) || files.find((f) => /\.gltf$/i.test(f.name));
      if (!main) throw new Error("Choose a .glb file, or a .gltf file with its buffers and images");
      doc = withCommon({ kind: "scene", scene: { gltf: main.name } }, main.name);
      const variant = $("#gltf-variant").value.trim();
      if (variant) doc.scene.gltf_variant = variant;
      // A still of the asset's animation: at a time, of an animation named or numbered (all digits: its index).
      const time = $("#anim-time").value.trim();
      if (time !== "") doc.scene.time = Number(time);
      const animation = $("#anim-name").value.trim();
      if (animation) doc.scene.animation = /^\d+$/.test(animation) ? Number(animation) : animation;
      // An environment map goes along as a file of the same request; the daemon stores it as an asset of its own.
      const env = $("#env-map").files[0];
      if (env) {
        if (files.some((f) => f.name === env.name)) throw new Error(`${env.name} is chosen twice`);
        const environment = { map: env.name };
        const intensity = Number($("#env-intensity").value || 1);
        const rotation = Number($("#env-rotation").value || 0);
        if (intensity !== 1) environment.intensity = intensity;
        if (rotation) environment.rotation_deg = rotation;
        doc.scene.environment = environment;
        files = [...files, env];
      }
    } else {
      try {
        doc = JSON.parse($("#json-doc").value);
      } catch (err) {
        throw new Error(`The job document is not valid JSON: ${err.message}`);
      }
    }
  } catch (err) {
    showError(err, "Cannot submit");
    return;
  }
  button.disabled = true;
  try {
    const job = files ? await api.submitMultipart(doc, files) : await api.submitJson(doc);
    showNotice(`Job ${jobLabel(job)} queued.`);
    // Submitted: the next submission starts unnamed, and an error about an earlier attempt is out of date.
    $("#job-name").value = "";
    clearErrors();
    followEnd(job);
    await refreshQueue();
    select(job.id);
  } catch (err) {
    showError(err, "Submit refused");
  } finally {
    button.disabled = false;
  }
});

// ---------------------------------------------------------------------------------------------------------------
// Queue

let jobs = [];
let filter = "all";
const rows = new Map(); // id -> { tr, cells }
let selectedId = null;

function buildFilters() {
  const group = $("#filters");
  for (const s of ["all", ...STATES]) {
    const b = document.createElement("button");
    b.type = "button";
    b.className = "chip";
    b.dataset.filter = s;
    b.setAttribute("aria-pressed", String(s === filter));
    b.innerHTML = `<span class="chip-label"></span> <span class="count"></span>`;
    b.querySelector(".chip-label").textContent = s;
    b.addEventListener("click", () => {
      filter = s;
      for (const c of group.children) c.setAttribute("aria-pressed", String(c.dataset.filter === s));
      renderQueue();
    });
    group.append(b);
  }
}
buildFilters();

function button(label, action, extraClass) {
  const b = document.createElement("button");
  b.type = "button";
  b.textContent = label;
  b.dataset.action = action;
  if (extraClass) b.className = extraClass;
  return b;
}

function makeRow(job) {
  const tr = document.createElement("tr");
  tr.dataset.id = job.id;
  const idCell = document.createElement("td");
  // The job's name, and under it the short id (what `tessera` commands take) and its kind.
  const link = document.createElement("button");
  link.type = "button";
  link.className = "link job-name";
  link.title = job.id;
  link.addEventListener("click", () => select(job.id));
  const kind = document.createElement("span");
  kind.className = "kind";
  const idText = document.createElement("span");
  idText.className = "mono job-id";
  idText.textContent = shortId(job.id);
  kind.append(idText, document.createTextNode(" "));
  const kindText = document.createTextNode("");
  kind.append(kindText);
  idCell.append(link, kind);

  const stateCell = document.createElement("td");
  stateCell.className = "col-state";
  const badge = document.createElement("span");
  badge.className = "badge";
  const reason = document.createElement("small");
  reason.className = "reason";
  stateCell.append(badge, reason);

  const prioCell = document.createElement("td");
  const prio = document.createElement("input");
  prio.type = "number";
  prio.min = -100;
  prio.max = 100;
  prio.step = 1;
  prio.className = "prio";
  prio.setAttribute("aria-label", `Priority of job ${shortId(job.id)}`);
  prio.addEventListener("change", () => changePriority(job.id, prio));
  prioCell.append(prio);

  const progCell = document.createElement("td");
  progCell.className = "col-progress";
  const bar = document.createElement("div");
  bar.className = "progress";
  bar.setAttribute("role", "progressbar");
  bar.setAttribute("aria-valuemin", "0");
  bar.setAttribute("aria-valuemax", "100");
  bar.setAttribute("aria-label", `Progress of job ${shortId(job.id)}`);
  bar.innerHTML = '<span class="bar"></span>';
  const progText = document.createElement("small");
  progText.className = "muted";
  progCell.append(bar, progText);

  const createdCell = document.createElement("td");
  createdCell.className = "muted nowrap";

  const actCell = document.createElement("td");
  actCell.className = "actions";
  const cancel = button("Cancel", "cancel");
  const requeue = button("Requeue", "requeue");
  const del = button("Delete", "delete", "danger");
  for (const b of [cancel, requeue, del]) {
    b.setAttribute("aria-label", `${b.textContent} job ${shortId(job.id)}`);
    b.addEventListener("click", () => runAction(job.id, b.dataset.action));
  }
  actCell.append(cancel, requeue, del);

  idCell.className = "col-job";
  prioCell.className = "col-prio";
  createdCell.classList.add("col-created");
  tr.append(idCell, stateCell, prioCell, progCell, createdCell, actCell);
  tr.addEventListener("click", (e) => {
    if (e.target.closest("button, input")) return;
    select(job.id);
  });
  return {
    tr, link, kindText, badge, reason, prio, bar, progText, createdCell, buttons: { cancel, requeue, delete: del },
  };
}

function updateRow(r, job) {
  r.link.textContent = job.name || shortId(job.id);
  r.link.setAttribute("aria-label", `Show job ${jobLabel(job)}`);
  r.kindText.textContent = job.kind;
  r.badge.textContent = job.state;
  r.badge.dataset.state = job.state;
  // Why a job failed, in its row: the start of it, the whole of it on hover and in the job view.
  r.reason.textContent = job.state === "failed" ? job.error || "" : "";
  r.reason.title = r.reason.textContent;
  if (document.activeElement !== r.prio) r.prio.value = job.priority ?? 0;
  r.prio.disabled = !allowed(job, "priority");
  setProgress(r.bar, job);
  r.progText.textContent = progressText(job);
  r.createdCell.textContent = fmtTime(job.created_at);
  for (const [action, b] of Object.entries(r.buttons)) b.disabled = !allowed(job, action);
  r.tr.classList.toggle("selected", job.id === selectedId);
  r.tr.setAttribute("aria-selected", String(job.id === selectedId));
}

function renderQueue() {
  const body = $("#jobs");
  const counts = Object.fromEntries(STATES.map((s) => [s, 0]));
  for (const j of jobs) counts[j.state] = (counts[j.state] || 0) + 1;
  for (const chip of $("#filters").children) {
    const s = chip.dataset.filter;
    chip.querySelector(".count").textContent = s === "all" ? jobs.length : counts[s] || 0;
  }
  const shown = jobs.filter((j) => filter === "all" || j.state === filter);
  const seen = new Set();
  let previous = null;
  for (const job of shown) {
    seen.add(job.id);
    let r = rows.get(job.id);
    if (!r) {
      r = makeRow(job);
      rows.set(job.id, r);
    }
    updateRow(r, job);
    const expectedPosition = previous ? previous.nextSibling : body.firstChild;
    if (r.tr !== expectedPosition) body.insertBefore(r.tr, expectedPosition);
    previous = r.tr;
  }
  for (const [id, r] of rows) {
    if (!seen.has(id)) {
      r.tr.remove();
      if (!jobs.some((j) => j.id === id)) rows.delete(id);
    }
  }
  $("#queue-empty").hidden = shown.length > 0;
  $("#queue-empty").textContent = jobs.length ? `No ${filter} jobs.` : "No jobs yet. Submit one on the left.";
  if (selectedId) updateCompareChoices();
}

let queueTimer = null;
let queueBusy = false;
// job id -> when the page last saw the job ended, and that status. A job list asked for before then may still show
// it running (the job's own stream, or an action's answer, told its end first): the ended status stands.
const endsObserved = new Map();
function fresher(job, askedAt) {
  const ended = endsObserved.get(job.id);
  return ended && ended.at > askedAt && !TERMINAL.has(job.state) ? ended.job : job;
}
// Refreshes the job list; returns how long the server asked to wait before the next refresh (0 if it did not).
async function refreshQueue() {
  if (queueBusy) return 0;
  queueBusy = true;
  try {
    const sent = performance.now();
    const list = await api.listJobs();
    jobs = (list.jobs || []).map((j) => fresher(j, sent));
    for (const j of jobs) noteJobState(j);
    renderQueue();
    const sel = jobs.find((j) => j.id === selectedId);
    if (sel && !watcher.live) showJob(sel);
  } catch (e) {
    // The connection indicator shows it; a toast per failed poll would drown the page. An overloaded server's
    // Retry-After is honoured: polling harder would only add to the load.
    return e instanceof ApiError && e.retryAfterMs ? e.retryAfterMs : 0;
  } finally {
    queueBusy = false;
  }
  return 0;
}
// The next refresh, after the usual interval or the longer wait the server asked for.
function scheduleQueue(wait = 0) {
  clearTimeout(queueTimer);
  queueTimer = setTimeout(async () => scheduleQueue(await refreshQueue()), Math.max(QUEUE_POLL_MS, wait));
}

async function changePriority(id, input) {
  const value = Number(input.value);
  if (!Number.isInteger(value) || value < -100 || value > 100) {
    showError(new Error("Priority must be a whole number from -100 to 100"), "Priority");
    return;
  }
  try {
    await api.setPriority(id, value);
    showNotice(`Job ${shortId(id)}: priority ${value}.`);
  } catch (e) {
    showError(e, "Priority change refused");
  }
  input.blur();
  refreshQueue();
}

// A job as the page knows it, by its id: for messages about it.
const knownJob = (id) => jobs.find((j) => j.id === id) || (currentJob?.id === id ? currentJob : { id });

function confirmDelete(id) {
  const dialog = $("#confirm");
  // Named as the queue names it (a name is what the user recognises), with the short id the command line takes.
  const job = knownJob(id);
  const what = job.name ? `“${job.name}” (${shortId(id)})` : shortId(id);
  $("#confirm-text").textContent = `Job ${what} and its images will be deleted. This cannot be undone.`;
  return new Promise((resolve) => {
    dialog.addEventListener("close", () => resolve(dialog.returnValue === "yes"), { once: true });
    dialog.returnValue = "no";
    dialog.showModal();
  });
}

async function runAction(id, action) {
  try {
    if (action === "delete") {
      if (!(await confirmDelete(id))) return;
      const label = jobLabel(knownJob(id));
      await api.remove(id);
      showNotice(`Job ${label} deleted.`);
      if (id === selectedId) select(null);
    } else {
      const job = await api.action(id, action);
      showNotice(`Job ${shortId(id)}: ${job?.state ?? action}.`);
      if (job && id === selectedId) showJob(job);
    }
  } catch (e) {
    showError(e, `${action[0].toUpperCase()}${action.slice(1)} refused`);
  }
  refreshQueue();
}

// ---------------------------------------------------------------------------------------------------------------
// Job view

let currentJob = null;

// Follows one job: SSE when the daemon has /events, else GET /v1/jobs/{id} every second. Calls showJob() with
// every status and loadPreview() whenever a newer preview exists.
class JobWatcher {
  constructor() {
    this.id = null;
    this.es = null;
    this.timer = null;
    this.live = false;
    this.lastPass = -1;
    this.errors = 0;
  }
  stop() {
    this.es?.close();
    this.es = null;
    clearTimeout(this.timer);
    this.timer = null;
    this.live = false;
    this.id = null;
    setLiveMode(null);
  }
  start(id) {
    this.stop();
    this.id = id;
    this.lastPass = -1;
    this.errors = 0;
    if (typeof EventSource === "undefined") return this.poll();
    let es;
    try {
      es = new EventSource(api.eventsUrl(id));
    } catch {
      return this.poll();
    }
    this.es = es;
    setLiveMode("connecting");
    es.addEventListener("open", () => {
      this.live = true;
      this.errors = 0;
      setLiveMode("sse");
    });
    es.addEventListener("state", (e) => {
      const job = JSON.parse(e.data);
      if (job.id !== this.id) return;
      showJob(job);
      this.previewIfNewer(job.progress?.passes ?? 0, job);
      if (TERMINAL.has(job.state)) {
        // The stream ends after the terminal state; do not let EventSource reconnect.
        es.close();
        this.live = false;
        setLiveMode("done");
      }
    });
    es.addEventListener("progress", (e) => {
      const d = JSON.parse(e.data);
      if (d.id !== this.id || !currentJob) return;
      showJob({ ...currentJob, progress: d.progress });
    });
    es.addEventListener("preview", (e) => {
      const d = JSON.parse(e.data);
      if (d.id !== this.id) return;
      if (d.pass > this.lastPass) {
        this.lastPass = d.pass;
        loadPreview(this.id, d.url);
      }
    });
    es.addEventListener("error", () => {
      if (this.es !== es) return;
      // CLOSED: the endpoint answered with an error (404 before the daemon has events, 401, ...): poll instead.
      // CONNECTING: EventSource retries by itself; after a few failures in a row, poll.
      this.errors += 1;
      if (es.readyState === EventSource.CLOSED || this.errors >= 3 || !this.live) {
        es.close();
        this.es = null;
        this.live = false;
        if (this.id === id) this.poll();
      } else {
        setLiveMode("reconnecting");
      }
    });
  }
  previewIfNewer(passes, job) {
    if (passes > 0 && passes !== this.lastPass && (job.links?.preview || passes > 0)) {
      this.lastPass = passes;
      loadPreview(job.id, `/v1/jobs/${encodeURIComponent(job.id)}/preview.png?pass=${passes}`);
    }
  }
  poll() {
    setLiveMode("polling");
    const id = this.id;
    const tick = async () => {
      if (this.id !== id) return;
      let job = null;
      let wait = 0;
      try {
        job = await api.getJob(id);
      } catch (e) {
        if (e instanceof ApiError && e.status === 404) {
          showError(e, `Job ${shortId(id)}`);
          select(null);
          return;
        }
        if (e instanceof ApiError && e.retryAfterMs) wait = e.retryAfterMs;
      }
      if (this.id !== id) return;
      if (job) {
        showJob(job);
        this.previewIfNewer(job.progress?.passes ?? 0, job);
        if (TERMINAL.has(job.state)) {
          setLiveMode("done");
          return;
        }
      }
      this.timer = setTimeout(tick, Math.max(JOB_POLL_MS, wait));
    };
    tick();
  }
}
const watcher = new JobWatcher();

function setLiveMode(mode) {
  const el = $("#live-mode");
  const labels = {
    connecting: "connecting…",
    sse: "live (events)",
    reconnecting: "reconnecting…",
    polling: "live (polling)",
    done: "finished",
  };
  el.hidden = !mode;
  el.dataset.mode = mode || "";
  el.textContent = labels[mode] || "";
}

// The viewer shows the latest preview (PNG) while a job renders, then its result: the linear EXR, on which
// exposure and the tone curve apply, or the PNG when the job has no EXR output.
const viewer = new ImageViewer($("#viewer"));
let previewSeq = 0;
let resultShown = null; // the id whose result the viewer shows: later previews are older than it
const imageCache = new Map(); // job id -> its decoded result, for the A/B comparison and reselection

// A job's result as the viewer takes it: the decoded EXR, or the PNG as a bitmap (no EXR output, or one this
// reader does not take).
async function resultImage(job) {
  const outputs = job.outputs || ["png", "exr"];
  const key = job.id;
  if (imageCache.has(key)) return imageCache.get(key);
  const url = (ext) => `/v1/jobs/${encodeURIComponent(job.id)}/result.${ext}`;
  let image = null;
  if (outputs.includes("exr")) {
    try {
      image = await decodeExr(await (await getBlob(url("exr"))).arrayBuffer());
    } catch (e) {
      if (!(e instanceof ExrError) || !outputs.includes("png")) throw e;
    }
  }
  image ??= await bitmapImage(await getBlob(url("png")));
  imageCache.set(key, image);
  while (imageCache.size > 6) imageCache.delete(imageCache.keys().next().value);
  return image;
}
async function bitmapImage(blob) {
  const bitmap = await createImageBitmap(blob);
  return { width: bitmap.width, height: bitmap.height, bitmap };
}

async function loadPreview(id, url) {
  if (resultShown === id) return;
  const seq = ++previewSeq;
  try {
    const blob = await getBlob(url);
    if (seq !== previewSeq || id !== selectedId || resultShown === id) return;
    const image = await bitmapImage(blob);
    if (seq !== previewSeq || id !== selectedId || resultShown === id) return;
    viewer.show(image, { keepView: true });
    $("#viewer").dataset.pass = String(watcher.lastPass);
    $("#preview-placeholder").hidden = true;
  } catch (e) {
    // 409 before the first pass, 404 when the job ended before one: nothing to show yet.
    if (!(e instanceof ApiError && (e.status === 409 || e.status === 404))) showError(e, "Preview");
  }
}

async function loadResult(job) {
  if (resultShown === job.id) return;
  resultShown = job.id;
  const seq = ++previewSeq;
  try {
    const image = await resultImage(job);
    if (seq !== previewSeq || job.id !== selectedId) return;
    viewer.show(image, { keepView: true });
    offerNoisyCompare(image);
    $("#viewer").dataset.pass = job.state === "succeeded" ? "final" : "partial";
    $("#viewer").dataset.aov = "beauty";
    $("#aov-view").value = "";
    $("#preview-placeholder").hidden = true;
  } catch (e) {
    if (job.id === selectedId) resultShown = null;
    showError(e, "Result image");
  }
}

// The render passes of a job with results, in the order the job asked for them: the viewer's Pass choices, beside
// the beauty. A pass shows as the daemon's PNG of it (links.aovs), its readout the values of its layer in the EXR.
function jobPasses(job) {
  const links = job.links?.aovs || {};
  const asked = Array.isArray(job.render?.aovs) ? job.render.aovs : Object.keys(links);
  return asked.filter((name) => links[name]);
}
function updatePassChoices(job) {
  const select = $("#aov-view");
  const passes = jobPasses(job);
  // Rebuilt only when the choices change: rebuilding closes a list the user has open.
  const signature = `${job.id} ${passes.join(" ")}`;
  if (select.dataset.signature === signature) return;
  select.dataset.signature = signature;
  const keep = select.value;
  select.replaceChildren(new Option("beauty", ""), ...passes.map((name) => new Option(name, name)));
  select.value = passes.includes(keep) ? keep : "";
  $("#aov-view-group").hidden = !passes.length;
}
async function showPass(job, pass) {
  if (!job || !allowed(job, "result")) return;
  const seq = ++previewSeq;
  try {
    const result = await resultImage(job);
    let image = result;
    if (pass) {
      const look = await bitmapImage(await getBlob(job.links.aovs[pass]));
      const layer = result.layers?.[pass];
      const crypto = layer ? null : cryptomatteOfPass(result, pass);
      image = { ...look, pass: { name: pass, channels: layer?.channels ?? [], values: layer?.values ?? null, crypto } };
    }
    if (seq !== previewSeq || job.id !== selectedId) return;
    resultShown = job.id;
    viewer.show(image, { keepView: true });
    $("#viewer").dataset.aov = pass || "beauty";
    $("#preview-placeholder").hidden = true;
  } catch (e) {
    showError(e, pass ? `Pass ${pass}` : "Result image");
  }
}
$("#aov-view").addEventListener("change", (e) => showPass(currentJob, e.target.value));

// A frame range job's frames (frames.js): the strip, the player and the scrubber. While the range renders and the user
// has picked nothing, the viewer shows the job's preview (its latest finished frame); a frame picked on the strip
// shows as a finished image (its EXR, else its PNG), a frame the player or the scrubber reaches as its PNG.
const frameStrip = new FrameStrip(
  {
    panel: $("#frames-panel"),
    strip: $("#frames-strip"),
    counts: $("#frames-counts"),
    play: $("#frames-play"),
    fps: $("#frames-fps"),
    scrubber: $("#frames-scrubber"),
    label: $("#frames-label"),
    earlier: $("#frames-earlier"),
    later: $("#frames-later"),
  },
  (frame, how, bitmap) => showFrame(currentJob, frame, how, bitmap),
);
async function frameImage(job, frame) {
  const outputs = job.outputs || ["png", "exr"];
  if (outputs.includes("exr")) {
    try {
      return await decodeExr(await (await getBlob(frameUrl(job.frames, frame, "exr"))).arrayBuffer());
    } catch (e) {
      if (!(e instanceof ExrError) || !outputs.includes("png")) throw e;
    }
  }
  return bitmapImage(await getBlob(frameUrl(job.frames, frame, "png")));
}
async function showFrame(job, frame, how, bitmap) {
  if (!job?.frames) return;
  const seq = ++previewSeq;
  // The frame shown stays until the user picks another: the job's later previews do not replace it.
  resultShown = job.id;
  try {
    const image = how === "play" ? { width: bitmap.width, height: bitmap.height, bitmap } : await frameImage(job, frame);
    if (seq !== previewSeq || job.id !== selectedId) return;
    viewer.show(image, { keepView: true });
    $("#viewer").dataset.pass = how === "play" ? "frame" : "final";
    $("#viewer").dataset.frame = String(frame);
    $("#preview-placeholder").hidden = true;
    $("#preview-caption").textContent = captionText(job);
  } catch (e) {
    showError(e, `Frame ${frame}`);
  }
  updateFrameDownloads(job);
}
// The frame shown, downloaded as PNG or EXR (when the job has that output and the frame is done).
function updateFrameDownloads(job) {
  const frame = frameStrip.current;
  for (const ext of ["png", "exr"]) {
    const ok = Boolean(job?.frames && frame != null && frameState(job.frames, frame) === "done" &&
      (job.outputs || ["png", "exr"]).includes(ext) && frameUrl(job.frames, frame, ext));
    $(`#frame-download-${ext}`).disabled = !ok;
  }
}
async function downloadFrame(ext) {
  const job = currentJob;
  const frame = frameStrip.current;
  if (!job?.frames || frame == null) return;
  try {
    saveBlob(await getBlob(frameUrl(job.frames, frame, ext)), `tessera-${shortId(job.id)}.frame-${frame}.${ext}`);
  } catch (e) {
    showError(e, `Download frame ${frame} ${ext.toUpperCase()}`);
  }
}
$("#frame-download-png").addEventListener("click", () => downloadFrame("png"));
$("#frame-download-exr").addEventListener("click", () => downloadFrame("exr"));

// The comparison (B) image: another finished job's result.
function updateCompareChoices() {
  const select = $("#compare");
  const keep = select.value;
  const options = [new Option("none", "")];
  for (const j of jobs) {
    if (j.id === selectedId || !allowed(j, "result")) continue;
    options.push(new Option(jobLabel(j), j.id));
  }
  // Rebuilt only when the choices change: rebuilding closes a list the user has open.
  const signature = options.map((o) => `${o.value} ${o.text}`).join("\n");
  if (select.dataset.signature === signature) return;
  select.dataset.signature = signature;
  select.replaceChildren(...options);
  select.value = options.some((o) => o.value === keep) ? keep : "";
  if (select.value !== keep && keep) viewer.compare(null);
}
$("#compare").addEventListener("change", async (e) => {
  $("#compare-noisy").setAttribute("aria-pressed", "false");
  const id = e.target.value;
  const job = jobs.find((j) => j.id === id);
  if (!job) return viewer.compare(null);
  try {
    const image = await resultImage(job);
    if ($("#compare").value === id) viewer.compare(image);
  } catch (err) {
    showError(err, `Compare with ${shortId(id)}`);
  }
});

// A denoised job's result holds the image as rendered as the layer "noisy" (R, G, B) beside the denoised beauty:
// one click compares the two, the denoised image as A (left of the wipe), the noisy one as B.
let noisyImage = null;
function offerNoisyCompare(image) {
  const noisy = image.layers?.noisy;
  const rgb = noisy && ["R", "G", "B"].every((c, i) => noisy.channels[i] === c) && noisy.channels.length === 3;
  noisyImage = rgb ? { width: image.width, height: image.height, rgb: noisy.values } : null;
  $("#compare-noisy").hidden = !noisyImage;
  $("#compare-noisy").setAttribute("aria-pressed", "false");
}
$("#compare-noisy").addEventListener("click", (e) => {
  const on = e.currentTarget.getAttribute("aria-pressed") !== "true" && noisyImage;
  $("#compare").value = "";
  e.currentTarget.setAttribute("aria-pressed", String(Boolean(on)));
  viewer.compare(on ? noisyImage : null);
});

function select(id) {
  if (id === selectedId) return;
  selectedId = id;
  previewSeq++;
  resultShown = null;
  viewer.clear();
  delete $("#viewer").dataset.pass;
  delete $("#viewer").dataset.aov;
  delete $("#viewer").dataset.frame;
  frameStrip.update(null);
  $("#compare").value = "";
  noisyImage = null;
  $("#compare-noisy").hidden = true;
  $("#compare-noisy").setAttribute("aria-pressed", "false");
  $("#aov-view").value = "";
  delete $("#aov-view").dataset.signature;
  $("#aov-view-group").hidden = true;
  $("#preview-placeholder").hidden = false;
  currentJob = null;
  for (const [rid, r] of rows) {
    r.tr.classList.toggle("selected", rid === id);
    r.tr.setAttribute("aria-selected", String(rid === id));
  }
  $("#job-empty").hidden = Boolean(id);
  $("#job-body").hidden = !id;
  $("#job-state").hidden = !id;
  $("#job-log").textContent = "";
  jobLog.id = null;
  if (!id) {
    watcher.stop();
    $("#job-title").textContent = "Job";
    return;
  }
  $("#job-title").textContent = `Job ${shortId(id)}`;
  const known = jobs.find((j) => j.id === id);
  updateCompareChoices();
  if (known) showJob(known);
  watcher.start(id);
}

// "4 of 9 done · unit 5 on n2 (31/128 spp) · 4 waiting · done by n1: 2, n2: 2", from the status's units.
function unitsText(u) {
  const parts = [`${u.done} of ${u.total} done`];
  for (const r of u.running) {
    // A unit whose node stopped renewing waits for its lease before another node takes it over.
    const wait = r.stalled ? `, ${r.node} not responding: taken over in ${fmtSeconds(r.takeover_in_s)}` : "";
    parts.push(`unit ${r.unit} on ${r.node} (${r.samples_done}/${r.samples} spp${wait})`);
  }
  if (u.queued) parts.push(`${u.queued} waiting`);
  const by = Object.entries(u.done_by_node).map(([node, n]) => `${node}: ${n}`);
  if (by.length) parts.push(`done by ${by.join(", ")}`);
  return parts.join(" · ");
}

// What the viewer shows: the pass and samples of the preview or result, or for a frame range the frame shown (one
// picked, played or scrubbed to) or its preview, the latest finished frame.
function captionText(job) {
  const p = job.progress || {};
  const shown = $("#viewer").dataset.frame;
  if (job.frames && shown !== undefined)
    return `Frame ${shown}${$("#viewer").dataset.pass === "final" ? " · final" : ""}`;
  if (job.frames && job.frames.done) return `Preview: the latest finished frame · ${job.frames.done} of ${job.frames.total} frames`;
  return p.passes
    ? `Pass ${p.passes} · ${adaptive(job) ? "mean " : ""}${p.samples_done} spp${
      job.state === "cancelled" ? " · partial: cancelled" : TERMINAL.has(job.state) ? " · final" : ""}`
    : job.state === "queued"
      ? "Waiting in the queue"
      : "";
}

function stat(dl, name, value) {
  const dt = document.createElement("dt");
  dt.textContent = name;
  const dd = document.createElement("dd");
  dd.textContent = value;
  dl.append(dt, dd);
}

function showJob(job) {
  if (job.id !== selectedId) return;
  noteJobState(job);
  const previous = currentJob;
  currentJob = job;
  const badge = $("#job-state");
  badge.textContent = job.state;
  badge.dataset.state = job.state;
  $("#job-failure").hidden = job.state !== "failed";
  $("#job-failure-text").textContent = job.error || "no reason was recorded";
  $("#job-title").textContent = `Job ${jobLabel(job)}`;
  $("#job-title").title = job.id;
  setProgress($("#job-progress"), job);
  for (const b of document.querySelectorAll("#job-body [data-action]")) {
    b.disabled = !allowed(job, b.dataset.action);
    b.onclick = () => runAction(job.id, b.dataset.action);
  }
  $("#download-png").disabled = !allowed(job, "result_png");
  $("#download-exr").disabled = !allowed(job, "result_exr");
  $("#duplicate").onclick = () => duplicate(job);
  $("#rerender").disabled = !canRerender(job);
  $("#rerender").onclick = () => rerender(job);

  const p = job.progress || {};
  const r = job.render || {};
  if (r.width && r.height) {
    // The frame takes the image's shape.
    $("#viewer .viewer-frame").style.aspectRatio = `${r.width} / ${r.height}`;
  }
  if (job.id !== previous?.id) viewer.settings(r.exposure_ev ?? 0, r.tonemap ?? "clamp");
  if (allowed(job, "result")) loadResult(job);
  updatePassChoices(job);
  frameStrip.update(job);
  updateFrameDownloads(job);
  refreshLog(job);
  const dl = $("#job-stats");
  dl.replaceChildren();
  if (job.name) stat(dl, "Name", job.name);
  stat(dl, "Id", job.id);
  stat(dl, "Kind", job.kind);
  if (r.width) stat(dl, "Resolution", `${r.width} × ${r.height}`);
  stat(dl, "Samples", samplesText(job, "per pixel"));
  if (adaptive(job)) stat(dl, "Adaptive threshold", r.min_spp ? `${r.adaptive_threshold}, min ${r.min_spp} spp` : `${r.adaptive_threshold}`);
  if (r.denoise && r.denoise !== "none") stat(dl, "Denoiser", r.denoise);
  stat(dl, "Passes", String(p.passes ?? 0));
  stat(dl, "Elapsed", fmtSeconds(p.elapsed_s));
  // A job split into work units: the render time of all its nodes together, and where its units are.
  if (job.units) {
    stat(dl, "Render time", `${fmtSeconds(p.render_s)} on all nodes`);
    stat(dl, "Units", unitsText(job.units));
  }
  if (job.state === "running") stat(dl, "ETA", fmtSeconds(p.eta_s));
  stat(dl, "Samples/s", fmtRate(p.samples_per_s));
  if (r.integrator) stat(dl, "Integrator", r.integrator);
  if (r.estimator) stat(dl, "Estimator", r.estimator);
  if (r.max_depth !== undefined) stat(dl, "Max depth", String(r.max_depth));
  if (r.seed !== undefined) stat(dl, "Seed", String(r.seed));
  if (r.time_limit_s) stat(dl, "Time limit", fmtSeconds(r.time_limit_s));
  stat(dl, "Priority", String(job.priority ?? 0));
  if (job.queue_position) stat(dl, "Queue position", String(job.queue_position));
  if (job.owner) stat(dl, "Owner", job.owner);
  stat(dl, "Created", fmtTime(job.created_at));
  if (job.started_at) stat(dl, "Started", fmtTime(job.started_at));
  if (job.finished_at) stat(dl, "Finished", fmtTime(job.finished_at));
  if (job.stop_reason) stat(dl, "Stopped by", job.stop_reason.replace("_", " "));
  for (const w of job.warnings || []) stat(dl, "Warning", w);
  $("#preview-caption").textContent = captionText(job);

  // Keep the queue row in step without waiting for the next poll.
  const i = jobs.findIndex((j) => j.id === job.id);
  if (i >= 0) {
    jobs[i] = { ...jobs[i], ...job };
    const row = rows.get(job.id);
    if (row) updateRow(row, jobs[i]);
  }
}

// The job's log, fetched when the job is selected, when its state or pass changes (at most every 2 s while it
// renders) and once it has ended; kept scrolled to the end unless the reader scrolled up.
const LOG_INTERVAL_MS = 2000;
const jobLog = { id: null, key: "", at: 0, timer: null };
function refreshLog(job) {
  const key = `${job.state} ${job.progress?.passes ?? 0}`;
  if (jobLog.id === job.id && jobLog.key === key) return;
  const fresh = jobLog.id !== job.id;
  jobLog.id = job.id;
  jobLog.key = key;
  clearTimeout(jobLog.timer);
  const wait = fresh || TERMINAL.has(job.state) ? 0 : Math.max(0, jobLog.at + LOG_INTERVAL_MS - Date.now());
  jobLog.timer = setTimeout(async () => {
    jobLog.at = Date.now();
    const id = job.id;
    const pre = $("#job-log");
    try {
      const text = await api.jobLog(id);
      if (id !== selectedId) return;
      const atEnd = pre.scrollTop + pre.clientHeight >= pre.scrollHeight - 4;
      pre.textContent = text || "Nothing yet: the log starts when the job starts rendering.";
      if (atEnd || fresh) pre.scrollTop = pre.scrollHeight;
      pre.dataset.state = job.state;
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 404)) showError(e, "Job log");
    }
  }, wait);
}

// Submitting a job again: Duplicate fills the form (the JSON tab, the name and the render settings) with the document
// the job was accepted with; Re-render submits it as it is. A job that failed on its input would fail the same way:
// it offers no Re-render (as it offers no Requeue).
const canRerender = (job) => TERMINAL.has(job.state) && !(job.state === "failed" && !allowed(job, "requeue"));
async function documentOf(job) {
  const doc = await api.document(job.id);
  if (!doc.name && job.name) doc.name = job.name;
  return doc;
}
async function duplicate(job) {
  try {
    const doc = await documentOf(job);
    $("#json-doc").value = JSON.stringify(doc, null, 2);
    fillRenderFields(doc.render, doc.outputs);
    $("#job-name").value = doc.name || "";
    selectTab($("#tab-json"), true);
    $("#submit-form").scrollIntoView({ block: "nearest" });
    showNotice(`The form holds the document of job ${jobLabel(job)}: change it and submit.`);
  } catch (e) {
    showError(e, "Duplicate");
  }
}
async function rerender(job) {
  const b = $("#rerender");
  b.disabled = true;
  try {
    const created = await api.submitJson(await documentOf(job));
    showNotice(`Job ${jobLabel(job)} submitted again as ${shortId(created.id)}.`);
    clearErrors();
    followEnd(created);
    await refreshQueue();
    select(created.id);
  } catch (e) {
    showError(e, "Re-render refused");
  } finally {
    if (currentJob?.id === job.id) b.disabled = !canRerender(currentJob);
  }
}

// Saves a fetched file under a name (the browser's download).
function saveBlob(blob, name) {
  const url = URL.createObjectURL(blob);
  const a = document.createElement("a");
  a.href = url;
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

async function download(ext) {
  if (!currentJob) return;
  const id = currentJob.id;
  const b = $(`#download-${ext}`);
  b.disabled = true;
  try {
    const blob = await getBlob(`/v1/jobs/${encodeURIComponent(id)}/result.${ext}`);
    // A cancelled job's image is what it rendered before the cancel.
    saveBlob(blob, `tessera-${shortId(id)}${currentJob?.state === "cancelled" ? "-partial" : ""}.${ext}`);
  } catch (e) {
    showError(e, `Download ${ext.toUpperCase()}`);
  } finally {
    if (currentJob?.id === id) b.disabled = !allowed(currentJob, `result_${ext}`);
  }
}
$("#download-png").addEventListener("click", () => download("png"));
$("#download-exr").addEventListener("click", () => download("exr"));

// ---------------------------------------------------------------------------------------------------------------
// A job that ends while the page is in the background (another tab, a minimised window): the one followed in the
// job view, or one submitted from this page. The tab's title says so ("✓ done: name — tessera") until the page is
// seen again, and, when the user ticked "Notify me", a notification too. The browser's permission is asked when the
// box is ticked, never when the page loads.

const PAGE_TITLE = document.title;
const ENDINGS = {
  succeeded: { mark: "✓", word: "done" },
  failed: { mark: "✗", word: "failed" },
  cancelled: { mark: "■", word: "cancelled" },
};
const submittedHere = new Set();
const lastStates = new Map(); // job id -> the state the page last saw it in
// job id -> the finished_at of the last end the page saw: an answer sent before that end and arriving after it (a
// job list and the job's own stream race) shows the job running again, and its next answer must not end it twice. A
// job requeued and ended again has another finished_at.
const endsSeen = new Map();
let endedUnseen = [];

function followEnd(job) {
  submittedHere.add(job.id);
  noteJobState(job);
}
// Called with every status the page sees (the job list, the followed job): a job seen running, queued or paused
// and now ended, while the page is hidden, is announced.
function noteJobState(job) {
  if (TERMINAL.has(job.state)) endsObserved.set(job.id, { at: performance.now(), job });
  const before = lastStates.get(job.id);
  lastStates.set(job.id, job.state);
  if (!before || TERMINAL.has(before) || !TERMINAL.has(job.state) || !ENDINGS[job.state]) return;
  if (endsSeen.get(job.id) === job.finished_at) return;
  endsSeen.set(job.id, job.finished_at);
  if (!document.hidden || !(job.id === selectedId || submittedHere.has(job.id))) return;
  endedUnseen.push(job);
  const ending = ENDINGS[job.state];
  if (endedUnseen.length === 1) {
    document.title = `${ending.mark} ${ending.word}: ${job.name || shortId(job.id)} — ${PAGE_TITLE}`;
  } else {
    const mark = endedUnseen.some((j) => j.state === "failed") ? ENDINGS.failed.mark : ending.mark;
    document.title = `${mark} ${endedUnseen.length} jobs ended — ${PAGE_TITLE}`;
  }
  notifyEnded(job);
}
// The page is seen again: the title goes back.
function seenEnded() {
  endedUnseen = [];
  document.title = PAGE_TITLE;
}

const NOTIFY_KEY = "tessera.notify";
const notifyBox = $("#notify");
const canNotify = () => "Notification" in window && Notification.permission === "granted";
function rememberNotify(on) {
  try {
    if (on) localStorage.setItem(NOTIFY_KEY, "1");
    else localStorage.removeItem(NOTIFY_KEY);
  } catch {
    // storage disabled: the choice lasts as long as the page
  }
}
if (!("Notification" in window)) {
  notifyBox.closest("label").hidden = true;
} else {
  // Ticked as the user left it, if the browser still allows notifications; nothing is asked here.
  try {
    notifyBox.checked = localStorage.getItem(NOTIFY_KEY) === "1" && canNotify();
  } catch {
    notifyBox.checked = false;
  }
}
notifyBox.addEventListener("change", async () => {
  if (notifyBox.checked && Notification.permission === "default") await Notification.requestPermission();
  if (notifyBox.checked && !canNotify()) {
    notifyBox.checked = false;
    showNotice("This browser blocks notifications from this page: the tab's title still tells when a job ends.");
  }
  rememberNotify(notifyBox.checked);
});
function notifyEnded(job) {
  if (!notifyBox.checked || !canNotify()) return;
  const body =
    job.state === "failed"
      ? job.error || "no reason was recorded"
      : `${job.state} · ${progressText(job)} · ${fmtSeconds(job.progress?.elapsed_s)}`;
  try {
    const n = new Notification(`tessera: ${job.name || shortId(job.id)} ${ENDINGS[job.state].word}`, {
      body,
      tag: `tessera-${job.id}`,
    });
    n.addEventListener("click", () => {
      window.focus();
      select(job.id);
      n.close();
    });
  } catch {
    // A browser that shows notifications from a service worker only (Chrome on Android): the title tells.
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Start

document.addEventListener("visibilitychange", () => {
  if (document.hidden) return;
  seenEnded();
  refreshQueue();
});
// The render settings' contract: the tone curves the viewer offers are the ones the daemon knows.
let renderSchema = null;
async function loadRenderSchema() {
  try {
    renderSchema = await api.schema("render.schema.json");
  } catch (e) {
    if (!(e instanceof ApiError && e.status === 401)) showError(e, "Loading the render settings");
    return;
  }
  const tones = renderSchema.properties?.tonemap?.enum || ["clamp"];
  const select = $("#tonemap-view");
  const keep = select.value;
  select.replaceChildren(...tones.map((t) => new Option(t, t)));
  select.value = tones.includes(keep) ? keep : tones[0];
  buildAovPicker(renderSchema.properties?.aovs?.items?.enum);
  // The form's choices are the contract's (an integrator added to the daemon appears here), with the labels the
  // page has for those it knows.
  for (const [sel, key, unset] of SELECT_SETTINGS) {
    const values = renderSchema.properties?.[key]?.enum;
    if (!values) continue;
    const form = $(sel);
    const chosen = form.value;
    const labels = new Map([...form.options].map((o) => [o.value, o.textContent]));
    const choices = unset === undefined ? values : ["", ...values];
    form.replaceChildren(...choices.map((v) => new Option(labels.get(v) || v || unset, v)));
    form.value = choices.includes(chosen) ? chosen : renderSchema.properties[key].default ?? values[0];
  }
  const limit = (sel, { minimum, maximum } = {}) => {
    if (minimum !== undefined) $(sel).min = minimum;
    if (maximum !== undefined) $(sel).max = maximum;
  };
  for (const [sel, key] of OPTIONAL_NUMBER_SETTINGS) limit(sel, renderSchema.properties?.[key]);
  for (const [sel, key] of FRAME_FIELDS) limit(sel, renderSchema.properties?.frames?.properties?.[key]);
}

loadExamples();
loadMaterials();
loadRenderSchema();
refreshQueue().then(scheduleQueue);
