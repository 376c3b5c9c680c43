// The web client, end to end: the real tesserad on a free port with a temporary data directory, Debian's chromium
// driven headless by playwright-core. Submits the Cornell example, watches the preview change, cancels and deletes
// another job, downloads the PNG, and saves a screenshot; submits every material model from the Material tab; checks
// the image viewer against the daemon's images, a failed job's reason, errors that cover nothing and the queue at a
// phone's width; jobs' names, their documents, Duplicate and Re-render, every render setting, an environment map from
// the glTF tab and a cancelled job's partial image; what users reported: the Name cleared after a submit and on a
// change of tab, one error banner, the material form's common parameters first and the rest under Advanced, Fit at
// most 1:1, the delete confirmation naming the job, the icon, every example of proto/examples, and the title (and a
// notification) when a job ends while the tab is hidden; render passes picked in the form and shown in the viewer;
// adaptive sampling set in the form and a denoised job's denoised/noisy compare; a frame range submitted from the
// form, its strip of frames filling, a frame picked and downloaded, and its frames played. Any failed step fails the test.
//
// node --test tests/browser/web_client_test.mjs   with   TESSERAD=path/to/tesserad  ARTIFACTS=dir
//   (CTest passes both; CHROMIUM overrides /usr/bin/chromium)
import assert from "node:assert/strict";
import { execFileSync, spawn } from "node:child_process";
import { createHash } from "node:crypto";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { createRequire } from "node:module";
import { after, before, test } from "node:test";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, "../..");
// playwright-core lives in tests/js (npm ci there); it never downloads a browser.
const require = createRequire(path.join(repo, "tests/js/package.json"));
const { chromium } = require("playwright-core");

const TESSERAD = process.env.TESSERAD || path.join(repo, "build/server/tesserad");
const ARTIFACTS = process.env.ARTIFACTS || path.join(repo, "build/artifacts");
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";

let daemon;
let baseUrl;
let context;
let page;
let tmp;
const pageErrors = [];

function startDaemon(dataDir) {
  return new Promise((resolve, reject) => {
    const child = spawn(
      TESSERAD,
      ["--port", "0", "--listen", "127.0.0.1", "--data-dir", dataDir, "--threads", "2", "--log-level", "warn"],
      { stdio: ["ignore", "pipe", "pipe"] },
    );
    let out = "";
    let err = "";
    const timer = setTimeout(() => reject(new Error(`tesserad did not start: ${out}${err}`)), 20000);
    child.stdout.on("data", (d) => {
      out += d;
      const m = out.match(/listening on (http:\/\/[^\s]+)/);
      if (m) {
        clearTimeout(timer);
        resolve({ child, url: m[1].replace(/\/$/, "") });
      }
    });
    child.stderr.on("data", (d) => {
      err += d;
      if (err.length > 20000) err = err.slice(-10000);
    });
    child.on("exit", (code) => {
      clearTimeout(timer);
      reject(new Error(`tesserad exited with ${code}: ${err}`));
    });
  });
}

before(async () => {
  assert.ok(fs.existsSync(TESSERAD), `no tesserad at ${TESSERAD}`);
  assert.ok(fs.existsSync(CHROMIUM), `no chromium at ${CHROMIUM} (deploy/install-deps.sh test installs it)`);
  tmp = fs.mkdtempSync(path.join(os.tmpdir(), "tessera-web-"));
  fs.mkdirSync(ARTIFACTS, { recursive: true });
  const d = await startDaemon(path.join(tmp, "data"));
  daemon = d.child;
  baseUrl = d.url;
  context = await chromium.launchPersistentContext(path.join(tmp, "profile"), {
    executablePath: CHROMIUM,
    headless: true,
    args: [
      "--headless",
      "--no-sandbox",
      "--disable-gpu",
      "--disable-quic",
      "--no-first-run",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
    ],
    viewport: { width: 1440, height: 1000 },
    acceptDownloads: true,
  });
  page = context.pages()[0] || (await context.newPage());
  page.setDefaultTimeout(30000);
  page.on("pageerror", (e) => pageErrors.push(`page error: ${e.message}`));
  page.on("console", (m) => {
    // HTTP errors (404 before a preview exists, the 422 provoked below) are the page's to show, not script errors.
    if (m.type() === "error" && !/Failed to load resource/.test(m.text())) pageErrors.push(`console: ${m.text()}`);
  });
});

after(async () => {
  await context?.close().catch(() => {});
  if (daemon && daemon.exitCode === null) {
    const exited = new Promise((r) => daemon.once("exit", r));
    daemon.kill("SIGTERM");
    await Promise.race([exited, new Promise((r) => setTimeout(r, 10000))]);
    if (daemon.exitCode === null) daemon.kill("SIGKILL");
  }
  if (tmp) fs.rmSync(tmp, { recursive: true, force: true });
});

// Steps run in order; after a failed one the rest are skipped (they depend on it).
let broken = false;
function step(t, name, fn) {
  return t.test(name, async (st) => {
    if (broken) return st.skip("an earlier step failed");
    try {
      await fn(st);
    } catch (e) {
      broken = true;
      throw e;
    }
  });
}

test("the web client submits, follows, cancels, deletes and downloads", async (t) => {
  await step(t, "the page loads and connects", async () => {
    const res = await page.goto(`${baseUrl}/`);
    assert.equal(res.status(), 200);
    for (const f of ["app.js", "api.js", "style.css"]) {
      const r = await page.request.get(`${baseUrl}/${f}`);
      assert.equal(r.status(), 200, `GET /${f}: tesserad must serve every file of clients/web`);
    }
    await page.locator('#connection[data-state="online"]').waitFor();
    // The material models arrived and generated controls.
    await page.locator("#material-type option").first().waitFor({ state: "attached" });
  });

  let mainId;
  await step(t, "submit the Cornell example at 128x128", async () => {
    await page.getByRole("tab", { name: "Example" }).click();
    await page.getByLabel("Example scene").selectOption("cornell");
    await page.getByLabel("Width").fill("128");
    await page.getByLabel("Height").fill("128");
    await page.getByLabel("Samples per pixel").fill("1024");
    await page.getByRole("button", { name: "Submit job" }).click();
    await page.locator("#job-title", { hasText: /Job Cornell box \([0-9a-f]{8}\)/ }).waitFor();
    mainId = await page.locator("#job-title").getAttribute("title");
    assert.match(mainId || "", /^[0-9a-zA-Z_-]+$/);
    // The queue calls it by the example's name, with the 8 digits of its id the command line takes.
    const row = page.locator(`#jobs tr[data-id="${mainId}"]`);
    await row.locator("button.link", { hasText: "Cornell box" }).waitFor();
    assert.equal(await row.locator(".job-id").textContent(), mainId.slice(0, 8));
    assert.equal((await (await page.request.get(`${baseUrl}/v1/jobs/${mainId}`)).json()).name, "Cornell box");
  });

  await step(t, "the preview changes at least twice while it renders", async () => {
    const seen = new Map(); // bytes hash -> pass
    const deadline = Date.now() + 90000;
    while (seen.size < 3 && Date.now() < deadline) {
      // What the viewer draws, and the pass it comes from.
      const shown = await page.evaluate(() => ({
        pass: document.querySelector("#viewer").dataset.pass,
        image: document.querySelector("#viewer canvas").toDataURL(),
      }));
      if (shown.pass && shown.pass !== "final") {
        const hash = createHash("sha256").update(shown.image).digest("hex");
        if (!seen.has(hash)) seen.set(hash, shown.pass);
      }
      const state = await page.locator("#job-state").textContent();
      if (state === "succeeded" && seen.size < 3) break;
      await page.waitForTimeout(100);
    }
    assert.ok(seen.size >= 3, `the preview showed ${seen.size} distinct images (passes ${[...seen.values()]})`);
    const mode = await page.locator("#live-mode").getAttribute("data-mode");
    assert.ok(["sse", "polling", "done"].includes(mode), `live mode ${mode}`);
  });

  await step(t, "another job is cancelled from the queue, then deleted with confirmation", async () => {
    await page.getByRole("tab", { name: "Example" }).click();
    await page.getByLabel("Example scene").selectOption("material");
    // A name typed in the form is the job's name.
    await page.getByLabel("Name", { exact: true }).fill("to be cancelled");
    await page.getByRole("button", { name: "Submit job" }).click();
    await page.getByLabel("Name", { exact: true }).fill("");
    // The new job is selected; find its row (the main job still renders, so this one waits in the queue).
    await page.waitForFunction((id) => {
      const t = document.querySelector("#job-title")?.title;
      return t && t !== id;
    }, mainId);
    const otherId = await page.locator("#job-title").getAttribute("title");
    const row = page.locator(`#jobs tr[data-id="${otherId}"]`);
    await row.waitFor();
    await row.locator("button.link", { hasText: "to be cancelled" }).waitFor();
    const cancel = row.getByRole("button", { name: /^Cancel job/ });
    await cancel.click();
    await row.locator('.badge[data-state="cancelled"]').waitFor();
    assert.ok(await cancel.isDisabled(), "Cancel stays disabled on a cancelled job");
    assert.ok(await row.getByRole("button", { name: /^Requeue job/ }).isEnabled(), "Requeue is offered");
    // Delete asks first: "Keep" keeps it, "Delete" deletes it.
    await row.getByRole("button", { name: /^Delete job/ }).click();
    await page.locator("#confirm[open]").waitFor();
    await page.locator("#confirm").getByRole("button", { name: "Keep" }).click();
    assert.equal(await row.count(), 1);
    await row.getByRole("button", { name: /^Delete job/ }).click();
    await page.locator("#confirm").getByRole("button", { name: "Delete" }).click();
    await row.waitFor({ state: "detached" });
    const gone = await page.request.get(`${baseUrl}/v1/jobs/${otherId}`);
    assert.equal(gone.status(), 404);
  });

  await step(t, "the Cornell job finishes and its PNG downloads", async () => {
    await page.locator(`#jobs tr[data-id="${mainId}"] button.link`).click();
    await page.locator('#job-state[data-state="succeeded"]').waitFor({ timeout: 180000 });
    const png = page.locator("#download-png");
    await png.waitFor();
    await page.waitForFunction(() => !document.querySelector("#download-png").disabled);
    const [download] = await Promise.all([page.waitForEvent("download"), png.click()]);
    const file = await download.path();
    const bytes = fs.readFileSync(file);
    assert.deepEqual([...bytes.subarray(0, 8)], [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a], "PNG signature");
    assert.match(download.suggestedFilename(), /\.png$/);
    // The job view shows its log, to its end.
    await page.locator("#job-log", { hasText: "succeeded: its samples-per-pixel budget was reached" }).waitFor();
    assert.match(await page.locator("#job-log").textContent(), /scene loaded in [\d.]+ s[\s\S]*pass 1: /);
  });

  await step(t, "a refused document shows the problem's title and every error", async () => {
    await page.getByRole("tab", { name: "JSON" }).click();
    await page
      .getByLabel("Job document")
      .fill('{"kind": "scene", "scene": {"objects": []}, "render": {"width": 0, "height": 0}}');
    await page.getByRole("button", { name: "Submit job" }).click();
    const toast = page.locator(".toast[role=alert]").last();
    await toast.waitFor();
    const text = await toast.textContent();
    assert.match(text, /422|Invalid/);
    const errors = await toast.locator("li").allTextContents();
    assert.ok(errors.some((e) => e.startsWith("/render/width: ")), `the width's error is listed: ${errors}`);
    assert.ok(errors.some((e) => e.startsWith("/render/height: ")), `the height's error is listed: ${errors}`);
    await toast.getByRole("button", { name: "Dismiss" }).click();
    await page.getByRole("tab", { name: "Example" }).click();
  });

  await step(t, "screenshot", async () => {
    await page.locator(`#jobs tr[data-id="${mainId}"] button.link`).click();
    await page.waitForTimeout(300);
    const shot = path.join(ARTIFACTS, "web-client.png");
    await page.screenshot({ path: shot, fullPage: true });
    assert.ok(fs.statSync(shot).size > 1000);
    console.log(`screenshot: ${shot}`);
  });

  await step(t, "no script errors on the page", () => {
    assert.deepEqual(pageErrors, []);
  });
});

// A job submitted through the API, followed to its end: { status, png } (png: the result's bytes when it succeeded).
async function renderThroughApi(doc) {
  const res = await page.request.post(`${baseUrl}/v1/jobs`, { data: doc });
  assert.equal(res.status(), 202, `submit ${JSON.stringify(doc)}: ${await res.text()}`);
  return finished((await res.json()).id);
}
async function finished(id) {
  const deadline = Date.now() + 60000;
  for (;;) {
    const status = await (await page.request.get(`${baseUrl}/v1/jobs/${id}`)).json();
    if (["succeeded", "failed", "cancelled"].includes(status.state)) {
      if (status.state !== "succeeded") return { status, png: null };
      return { status, png: await (await page.request.get(`${baseUrl}/v1/jobs/${id}/result.png`)).body() };
    }
    assert.ok(Date.now() < deadline, `job ${id} still ${status.state} after 60 s`);
    await page.waitForTimeout(100);
  }
}
// Clicks "Submit job" and returns the daemon's answer to the page's POST /v1/jobs.
async function submitResponse() {
  const [res] = await Promise.all([
    page.waitForResponse((r) => r.request().method() === "POST" && new URL(r.url()).pathname === "/v1/jobs"),
    page.getByRole("button", { name: "Submit job" }).click(),
  ]);
  return res;
}
// Clicks "Submit job" and returns the document the page sent and the job it made, followed to its end.
async function submitFromForm() {
  const [req] = await Promise.all([
    page.waitForRequest((r) => r.method() === "POST" && new URL(r.url()).pathname === "/v1/jobs"),
    page.getByRole("button", { name: "Submit job" }).click(),
  ]);
  const res = await req.response();
  const sent = JSON.parse(req.postData());
  assert.equal(res.status(), 202, `the form's ${JSON.stringify(sent.material)} was refused: ${await res.text()}`);
  return { sent, ...(await finished((await res.json()).id)) };
}

// The Material tab sends what it shows: every model submits with the form's defaults and renders exactly as the
// same material with every default of GET /v1/materials written out; changing its main control (roughness where it
// has one, else its first slider, number, colour or JSON field) sends the value shown and changes the image.
test("every material model renders from the form as shown, with its defaults and with a changed control", async (t) => {
  await page.goto(`${baseUrl}/`);
  const catalog = (await (await page.request.get(`${baseUrl}/v1/materials`)).json()).materials;
  const { NOT_ON_PREVIEW_STAGE } = await import(path.join(repo, "clients/web/materials.js"));
  const materials = catalog.filter((m) => !NOT_ON_PREVIEW_STAGE.includes(m.type));
  assert.ok(materials.length >= 15, `${materials.length} models`);
  await page.getByRole("tab", { name: "Material" }).click();
  // The tab offers every model of the catalogue but those the preview stage would show nothing of.
  const offered = await page.locator("#material-type option").evaluateAll((os) => os.map((o) => o.value));
  assert.deepEqual(offered, materials.map((m) => m.type));
  assert.ok(catalog.some((m) => m.type === "interface") && !offered.includes("interface"));
  await page.getByLabel("Width").fill("24");
  await page.getByLabel("Height").fill("24");
  await page.getByLabel("Samples per pixel").fill("4");
  // The path tracer: an earlier example may have left bdpt chosen, which refuses subsurface materials.
  await page.getByLabel("Integrator").selectOption("path");
  const pngs = new Map();
  for (const model of materials) {
    await t.test(model.type, async () => {
      await page.getByLabel("Material model").selectOption(model.type);
      const params = page.locator("#material-params");
      await params.locator(".material-params").waitFor();
      const defaults = Object.fromEntries(
        model.parameters.filter((p) => p.default != null).map((p) => [p.name, p.default]),
      );
      // The controls show the catalog's defaults; a parameter without one shows no value until it is set.
      for (const p of model.parameters) {
        const row = params.locator(`[data-param="${p.name}"]`);
        if (p.default == null) {
          const set = row.getByRole("checkbox", { name: `Set ${p.name}` });
          if (await set.count()) assert.ok(!(await set.isChecked()), `${model.type}.${p.name} starts unset`);
          continue;
        }
        const number = row.locator('input[type="number"]');
        if (typeof p.default === "number" && (await number.count()) === 1)
          assert.equal(Number(await number.inputValue()), p.default, `${model.type}.${p.name} shows its default`);
        if (typeof p.default === "string") assert.equal(await row.locator("select").inputValue(), p.default);
      }

      const plain = await submitFromForm();
      assert.equal(plain.status.state, "succeeded", `${model.type} with the form's defaults: ${plain.status.error}`);
      assert.equal(plain.sent.material.type, model.type);
      const material = { ...defaults, ...plain.sent.material };
      // The same render settings as the form sent (it shows a seed, a depth, ... too).
      const explicit = await renderThroughApi({ kind: "material", material, render: plain.sent.render });
      assert.equal(explicit.status.state, "succeeded", explicit.status.error);
      assert.ok(plain.png.equals(explicit.png), `${model.type}: the form renders unlike its defaults written out`);
      pngs.set(model.type, plain.png);

      // The main control, changed: roughness where the model has it, else its first slider, number, colour or JSON.
      const [name, control] = await page.evaluate(() => {
        const rows = [...document.querySelectorAll("#material-params .material-params > [data-param]")];
        for (const sel of ['input[type="range"]', 'input[type="number"]', 'input[type="color"]', "textarea"]) {
          const found = rows.filter((r) => [...r.querySelectorAll(sel)].some((x) => !x.closest("[hidden]")));
          const row = found.find((r) => r.dataset.param === "roughness") || found[0];
          if (row) return [row.dataset.param, sel];
        }
        return [null, null];
      });
      assert.ok(name, `${model.type}: no control to change`);
      const row = params.locator(`[data-param="${name}"]`);
      const input = row.locator(control).first();
      if (control.includes("range")) {
        const p = model.parameters.find((q) => q.name === name);
        const [lo, hi] = [p.minimum, p.maximum];
        await input.fill(String(defaults[name] < (lo + hi) / 2 ? lo + 0.8 * (hi - lo) : lo + 0.2 * (hi - lo)));
      } else if (control.includes("number")) {
        await input.fill(String(Number(await input.inputValue()) * 4 + 2));
      } else if (control.includes("color")) {
        await input.fill("#3366cc");
      } else {
        await input.fill(JSON.stringify({ type: "lambert", albedo: [0.1, 0.5, 0.9] }));
      }
      const changed = await submitFromForm();
      assert.equal(changed.status.state, "succeeded", `${model.type} with ${name} changed: ${changed.status.error}`);
      const v = changed.sent.material[name];
      assert.ok(v !== undefined, `${model.type}: the changed ${name} was not sent`);
      const shown = row.locator('input[type="number"]').first();
      if (typeof v === "number") assert.equal(v, Number(await shown.inputValue()), `${name} sent as shown`);
      assert.ok(!changed.png.equals(plain.png), `${model.type}: ${name} = ${JSON.stringify(v)} left the image alone`);
      const again = await renderThroughApi({
        kind: "material",
        material: { ...defaults, ...changed.sent.material },
        render: changed.sent.render,
      });
      assert.ok(changed.png.equals(again.png), `${model.type}: with ${name} changed, the form's render differs`);
    });
  }

  await t.test("a named metal is not overridden by eta and k the form did not set", async () => {
    await page.getByLabel("Material model").selectOption("conductor");
    await page.locator('[data-param="metal"] select').selectOption("copper");
    const copper = await submitFromForm();
    assert.deepEqual(copper.sent.material, { type: "conductor", metal: "copper" });
    assert.equal(copper.status.state, "succeeded");
    assert.ok(!copper.png.equals(pngs.get("conductor")), "copper renders as gold");
    // An override is sent once it is set, with the value its control shows.
    const row = page.locator('[data-param="alpha_x"]');
    assert.ok(await row.locator(".slider-row").isHidden(), "an unset override shows no value");
    // The overrides are Advanced: folded until opened.
    assert.ok(await row.isHidden(), "alpha_x is folded");
    await page.locator("#material-params summary", { hasText: "Advanced" }).click();
    await row.getByRole("checkbox", { name: "Set alpha_x" }).check();
    await row.locator('input[type="number"]').fill("0.5");
    const set = await submitFromForm();
    assert.deepEqual(set.sent.material, { type: "conductor", metal: "copper", alpha_x: 0.5 });
    assert.equal(set.status.state, "succeeded");
  });

  // A preset chooses its model and sets its parameters as shown (colours through the picker's 8-bit sRGB, so within
  // 0.01); each renders, differently; choosing a model by hand leaves the preset.
  await t.test("a subsurface preset sets the model and its parameters on the preview stage", async () => {
    const { MATERIAL_PRESETS } = await import(path.join(repo, "clients/web/materials.js"));
    const names = await page.locator("#material-preset option").evaluateAll((os) => os.map((o) => o.value));
    assert.deepEqual(names, ["", ...MATERIAL_PRESETS.map((p) => p.name)]);
    const rendered = [];
    for (const name of ["Wax", "Jade"]) {
      const preset = MATERIAL_PRESETS.find((p) => p.name === name).material;
      await page.getByLabel("Preset").selectOption(name);
      assert.equal(await page.getByLabel("Material model").inputValue(), "subsurface");
      const job = await submitFromForm();
      assert.equal(job.sent.material.type, "subsurface");
      for (const [key, value] of Object.entries(preset)) {
        if (key === "type") continue;
        const sent = [job.sent.material[key]].flat(), want = [value].flat();
        assert.equal(sent.length, want.length, `${name}.${key}: sent ${JSON.stringify(job.sent.material[key])}`);
        sent.forEach((v, i) => assert.ok(Math.abs(v - want[i]) <= 0.01, `${name}.${key}: sent ${v}, preset ${want[i]}`));
      }
      assert.equal(job.status.state, "succeeded", JSON.stringify(job.status.error));
      rendered.push(job.png);
    }
    assert.ok(!rendered[0].equals(rendered[1]), "wax and jade render alike");
    await page.getByLabel("Material model").selectOption("lambert");
    assert.equal(await page.getByLabel("Preset").inputValue(), "");
  });
  assert.deepEqual(pageErrors, []);
});

// The pixels of a PNG the daemon wrote, decoded by the page as it comes (no colour conversion), and of what the
// viewer's canvas shows: { width, height, data: RGBA bytes }.
async function pngPixels(url) {
  return page.evaluate(async (u) => {
    const bitmap = await createImageBitmap(await (await fetch(u)).blob(), { colorSpaceConversion: "none" });
    const c = new OffscreenCanvas(bitmap.width, bitmap.height);
    const ctx = c.getContext("2d");
    ctx.drawImage(bitmap, 0, 0);
    return { width: c.width, height: c.height, data: [...ctx.getImageData(0, 0, c.width, c.height).data] };
  }, url);
}
async function canvasPixels() {
  return page.evaluate(() => {
    const c = document.querySelector("#viewer canvas");
    const d = c.getContext("2d").getImageData(0, 0, c.width, c.height);
    return { width: c.width, height: c.height, data: [...d.data] };
  });
}
const viewState = async () => {
  const v = page.locator("#viewer");
  const [x, y] = (await v.getAttribute("data-pan")).split(" ").map(Number);
  return { zoom: Number(await v.getAttribute("data-zoom")), x, y };
};
// The largest difference, over the image, between what the canvas shows (at 1:1) and a PNG's pixels.
function largestDifference(canvas, png, view, region = () => true) {
  let worst = 0;
  for (let y = 0; y < png.height; ++y) {
    for (let x = 0; x < png.width; ++x) {
      const cx = view.x + x;
      if (!region(cx)) continue;
      const c = 4 * ((view.y + y) * canvas.width + cx);
      const p = 4 * (y * png.width + x);
      for (let k = 0; k < 3; ++k) worst = Math.max(worst, Math.abs(canvas.data[c + k] - png.data[p + k]));
    }
  }
  return worst;
}
// Every pixel of an EXR as OpenImageIO reads it.
function exrReference(bytes) {
  const file = path.join(tmp, `ref-${createHash("sha256").update(bytes).digest("hex").slice(0, 12)}.exr`);
  fs.writeFileSync(file, bytes);
  const text = execFileSync("oiiotool", ["--dumpdata", file], { encoding: "utf8", maxBuffer: 64 << 20 });
  const px = new Map();
  for (const m of text.matchAll(/Pixel \((\d+), (\d+)\): (\S+) (\S+) (\S+)/g)) {
    px.set(`${m[1]} ${m[2]}`, m.slice(3).map(Number));
  }
  return px;
}

// The job view's viewer: the linear EXR drawn with the job's exposure and tone curve reproduces the daemon's PNG;
// other settings reproduce the PNG of a job rendered with them; the readout gives the EXR's values; zoom above 1:1
// keeps pixels whole; dragging pans; Compare shows another job to the right of the split.
test("the viewer draws the EXR as the daemon's PNG, reads out, zooms, pans and compares", async (t) => {
  await page.goto(`${baseUrl}/`);
  const render = { width: 48, height: 40, spp: 16, seed: 3 };
  const material = { type: "conductor", metal: "copper", roughness: 0.3 };
  const submit = async (doc) => (await (await page.request.post(`${baseUrl}/v1/jobs`, { data: doc })).json()).id;
  const bright = await submit({ kind: "material", material, render: { ...render, exposure_ev: 1.5, tonemap: "aces" } });
  const plain = await submit({ kind: "material", material, render });
  const other = await submit({ kind: "material", material: { type: "lambert", albedo: [0.2, 0.4, 0.8] }, render });
  for (const id of [bright, plain, other]) assert.equal((await finished(id)).status.state, "succeeded");
  const brightPng = await pngPixels(`${baseUrl}/v1/jobs/${bright}/result.png`);
  const plainPng = await pngPixels(`${baseUrl}/v1/jobs/${plain}/result.png`);
  const otherPng = await pngPixels(`${baseUrl}/v1/jobs/${other}/result.png`);
  const exr = exrReference(await (await page.request.get(`${baseUrl}/v1/jobs/${bright}/result.exr`)).body());
  let box; // the canvas, once the job's view shows

  await t.test("at the job's own exposure and tone curve, the EXR looks as the daemon's PNG", async () => {
    await page.locator(`#jobs tr[data-id="${bright}"] button.link`).click();
    await page.locator('#viewer[data-source="linear"][data-pass="final"]').waitFor();
    box = await page.locator("#viewer canvas").boundingBox();
    assert.equal(await page.getByLabel("Exposure in stops").inputValue(), "1.5");
    assert.equal(await page.locator("#tonemap-view").inputValue(), "aces");
    await page.getByRole("button", { name: "1:1" }).click();
    const view = await viewState();
    assert.equal(view.zoom, 1);
    const d = largestDifference(await canvasPixels(), brightPng, view);
    assert.ok(d <= 1, `the viewer differs from the daemon's PNG by ${d} of 255`);
  });

  await t.test("other settings look as a job rendered with them", async () => {
    await page.getByLabel("Exposure in stops").fill("0");
    await page.getByLabel("Exposure in stops").press("Enter");
    await page.locator("#tonemap-view").selectOption("clamp");
    const d = largestDifference(await canvasPixels(), plainPng, await viewState());
    assert.ok(d <= 1, `exposure 0, clamp: the viewer differs from that job's PNG by ${d} of 255`);
  });

  await t.test("the readout gives the EXR's linear values under the cursor", async () => {
    const view = await viewState();
    await page.mouse.move(box.x + view.x + 30.5, box.y + view.y + 17.5);
    const text = await page.locator("#viewer .readout").textContent();
    const m = text.match(/x (\d+), y (\d+): R (\S+) G (\S+) B (\S+)/);
    assert.ok(m, `readout "${text}"`);
    assert.deepEqual([m[1], m[2]], ["30", "17"]);
    const want = exr.get("30 17");
    for (let k = 0; k < 3; ++k) {
      const got = Number(m[3 + k]);
      const tolerance = 1e-3 * Math.max(1e-3, Math.abs(want[k])); // the readout has 4 significant digits
      assert.ok(Math.abs(got - want[k]) <= tolerance, `${"RGB"[k]} ${got}, not ${want[k]}`);
    }
  });

  await t.test("zoom above 1:1 keeps each pixel whole, and dragging pans", async () => {
    await page.getByRole("button", { name: "Zoom in" }).click();
    await page.getByRole("button", { name: "Zoom in" }).click();
    const view = await viewState();
    assert.equal(view.zoom, 4);
    assert.match(await page.locator("#viewer .zoom").textContent(), /400%/);
    const pixels = await canvasPixels();
    // Image pixel (20, 12) covers 4 x 4 screen pixels, all of its PNG colour.
    const p = 4 * (12 * plainPng.width + 20);
    for (let dy = 0; dy < 4; ++dy) {
      for (let dx = 0; dx < 4; ++dx) {
        const c = 4 * ((view.y + 48 + dy) * pixels.width + view.x + 80 + dx);
        for (let k = 0; k < 3; ++k) {
          assert.ok(Math.abs(pixels.data[c + k] - plainPng.data[p + k]) <= 1, `screen pixel (${dx}, ${dy}) of it`);
        }
      }
    }
    // Drag by (40, 24) screen pixels: the image moves with the pointer, 10 by 6 of its pixels at 400 %.
    const at = [box.x + box.width / 2, box.y + box.height / 2];
    await page.mouse.move(...at);
    const before = (await page.locator("#viewer .readout").getAttribute("data-x")) | 0;
    const beforeY = (await page.locator("#viewer .readout").getAttribute("data-y")) | 0;
    await page.mouse.down();
    await page.mouse.move(at[0] + 40, at[1] + 24, { steps: 4 });
    await page.mouse.up();
    const moved = await viewState();
    assert.deepEqual([moved.x - view.x, moved.y - view.y], [40, 24]);
    await page.mouse.move(...at);
    const readout = page.locator("#viewer .readout");
    assert.deepEqual([Number(await readout.getAttribute("data-x")), Number(await readout.getAttribute("data-y"))],
      [before - 10, beforeY - 6]);
  });

  await t.test("Compare shows another job to the right of the split", async () => {
    await page.getByRole("button", { name: "1:1" }).click();
    await page.locator("#compare").selectOption(other);
    await page.locator('#viewer[data-compare="on"]').waitFor();
    const view = await viewState();
    const pixels = await canvasPixels();
    const split = Math.round(pixels.width / 2);
    const left = largestDifference(pixels, plainPng, view, (cx) => cx < split - 2);
    const right = largestDifference(pixels, otherPng, view, (cx) => cx > split + 2);
    assert.ok(left <= 1 && right <= 1, `left of the split differs by ${left}, right by ${right}`);
    await page.mouse.move(box.x + view.x + 5.5, box.y + view.y + 5.5);
    assert.match(await page.locator("#viewer .readout").textContent(), /A R \S+ G \S+ B \S+ · B R /);
    await page.locator("#compare").selectOption("");
    await page.locator('#viewer[data-compare="off"]').waitFor();
  });
  assert.deepEqual(pageErrors, []);
});

// One channel of an EXR as OpenImageIO reads it ("depth.Z"), by pixel: "x y" -> value.
function exrChannel(bytes, channel) {
  const file = path.join(tmp, `ch-${createHash("sha256").update(bytes).digest("hex").slice(0, 12)}.exr`);
  const one = `${file}.${channel}.exr`;
  fs.writeFileSync(file, bytes);
  execFileSync("oiiotool", [file, "--ch", channel, "-o", one]);
  const text = execFileSync("oiiotool", ["--dumpdata", one], { encoding: "utf8", maxBuffer: 64 << 20 });
  return new Map([...text.matchAll(/Pixel \((\d+), (\d+)\): (\S+)/g)].map((m) => [`${m[1]} ${m[2]}`, Number(m[3])]));
}
const canvasHash = async () => createHash("sha256").update(JSON.stringify((await canvasPixels()).data)).digest("hex");

// Render passes: the form offers the contract's passes (render.schema.json) and sends those picked as render.aovs;
// the job view offers the beauty and exactly those passes; a pass shows as the daemon's PNG of it, and the readout
// gives the pass's own values from the EXR (a depth, an object id); a job without passes offers no choice.
test("render passes are picked in the form and shown in the viewer with their values", async (t) => {
  await page.setViewportSize({ width: 1440, height: 1000 });
  await page.goto(`${baseUrl}/`);
  await page.locator('#connection[data-state="online"]').waitFor();
  const schema = await (await page.request.get(`${baseUrl}/v1/schemas/render.schema.json`)).json();
  let job;
  let exr;

  await t.test("the form offers the contract's passes and sends the two picked", async () => {
    await page.locator("#aov-depth").waitFor({ state: "attached" });
    const offered = await page.locator("#aovs input[type=checkbox]").evaluateAll((bs) => bs.map((b) => b.value));
    assert.deepEqual(offered, schema.properties.aovs.items.enum);
    await page.getByRole("tab", { name: "Example" }).click();
    await page.getByLabel("Example scene").selectOption("material");
    await page.getByLabel("Width").fill("48");
    await page.getByLabel("Height").fill("40");
    await page.getByLabel("Samples per pixel").fill("8");
    await page.getByLabel("Integrator").selectOption("path");
    await page.locator("#aovs-details > summary").click();
    await page.getByRole("checkbox", { name: "object_id", exact: true }).check();
    await page.getByRole("checkbox", { name: "depth", exact: true }).check();
    await page.getByRole("checkbox", { name: "crypto_material", exact: true }).check();
    job = await submitFromForm();
    assert.equal(job.status.state, "succeeded", job.status.error);
    assert.deepEqual(job.sent.render.aovs, ["depth", "object_id", "crypto_material"]);
    assert.deepEqual(job.status.render.aovs, ["depth", "object_id", "crypto_material"]);
    assert.deepEqual(Object.keys(job.status.links.aovs).sort(), ["crypto_material", "depth", "object_id"]);
    exr = await (await page.request.get(`${baseUrl}/v1/jobs/${job.status.id}/result.exr`)).body();
  });

  await t.test("the job view offers the beauty and exactly those passes", async () => {
    await page.locator(`#job-title[title="${job.status.id}"]`).waitFor();
    await page.locator('#viewer[data-pass="final"][data-aov="beauty"][data-source="linear"]').waitFor();
    await page.locator("#aov-view").waitFor();
    const options = await page.locator("#aov-view option").evaluateAll((os) => os.map((o) => o.textContent));
    assert.deepEqual(options, ["beauty", "depth", "object_id", "crypto_material"]);
  });

  await t.test("a pass shows the daemon's look of it and reads out its own values", async () => {
    await page.getByRole("button", { name: "1:1" }).click();
    const beauty = await canvasHash();
    const box = await page.locator("#viewer canvas").boundingBox();
    for (const [pass, channel] of [["depth", "Z"], ["object_id", "X"]]) {
      await page.locator("#aov-view").selectOption(pass);
      await page.locator(`#viewer[data-aov="${pass}"][data-source="display"]`).waitFor();
      const view = await viewState();
      assert.equal(view.zoom, 1);
      assert.notEqual(await canvasHash(), beauty, `${pass}: the shown image changed`);
      const look = await pngPixels(`${baseUrl}/v1/jobs/${job.status.id}/aovs/${pass}.png`);
      const d = largestDifference(await canvasPixels(), look, view);
      assert.ok(d <= 1, `${pass}: the viewer differs from the daemon's PNG of it by ${d} of 255`);
      // The look is the daemon's: exposure and tone curve do not apply to it.
      assert.ok(await page.getByLabel("Exposure in stops").isDisabled());
      await page.mouse.move(box.x + view.x + 24.5, box.y + view.y + 20.5);
      const text = await page.locator("#viewer .readout").textContent();
      const m = text.match(new RegExp(`^x 24, y 20: ${pass} ${channel} (\\S+)$`));
      assert.ok(m, `readout "${text}"`);
      const want = exrChannel(exr, `${pass}.${channel}`).get("24 20");
      assert.ok(Number.isFinite(want) && want > 0, `${pass} at the centre: ${want}`);
      if (pass === "object_id") assert.equal(Number(m[1]), want, "an object id reads out whole");
      else assert.ok(Math.abs(Number(m[1]) - want) <= 1e-3 * want, `${pass} ${m[1]}, not ${want}`);
    }
    // A Cryptomatte pass reads out the names of the pixel's materials (the EXR's manifest) and their coverage.
    await page.locator("#aov-view").selectOption("crypto_material");
    await page.locator('#viewer[data-aov="crypto_material"][data-source="display"]').waitFor();
    const view = await viewState();
    await page.mouse.move(box.x + view.x + 24.5, box.y + view.y + 20.5);
    const text = await page.locator("#viewer .readout").textContent();
    const m = text.match(/^x 24, y 20: crypto_material (.+) (\d+\.\d) %$/);
    assert.ok(m, `readout "${text}"`);
    assert.ok(!/^[0-9a-f]{8}$/.test(m[1]), `the material is named (${m[1]}), not its id's bits`);
    assert.ok(Number(m[2]) > 50, `the material at the centre covers ${m[2]} %`);
    await page.locator("#aov-view").selectOption("beauty");
    await page.locator('#viewer[data-aov="beauty"][data-source="linear"]').waitFor();
    assert.equal(await canvasHash(), beauty, "the beauty is shown again as it was");
    assert.ok(await page.getByLabel("Exposure in stops").isEnabled());
  });

  await t.test("a job without passes offers no choice of pass", async () => {
    const plain = await renderThroughApi({ kind: "material", material: { type: "lambert" },
      render: { width: 16, height: 16, spp: 2 } });
    assert.equal(plain.status.state, "succeeded");
    await page.locator(`#jobs tr[data-id="${plain.status.id}"] button.link`).click();
    await page.locator('#viewer[data-pass="final"][data-aov="beauty"][data-source="linear"]').waitFor();
    assert.ok(await page.locator("#aov-view-group").isHidden());
  });
  assert.deepEqual(pageErrors, []);
});

// The denoiser: the form offers the contract's denoisers (render.schema.json) and sends the one chosen.
test("the denoiser is chosen in the form and sent as render.denoise", async () => {
  await page.goto(`${baseUrl}/`);
  await page.locator('#connection[data-state="online"]').waitFor();
  const schema = await (await page.request.get(`${baseUrl}/v1/schemas/render.schema.json`)).json();
  await page.locator('#denoise option[value="regression"]').waitFor({ state: "attached" });
  const denoisers = await page.locator("#denoise option").evaluateAll((os) => os.map((o) => o.value));
  assert.deepEqual(denoisers, ["", ...schema.properties.denoise.enum]);
  await page.getByRole("tab", { name: "Example" }).click();
  await page.getByLabel("Example scene").selectOption("material");
  await page.getByLabel("Width").fill("48");
  await page.getByLabel("Height").fill("40");
  await page.getByLabel("Samples per pixel").fill("8");
  await page.getByLabel("Integrator").selectOption("path");
  await page.getByLabel("Denoiser").selectOption("regression");
  const job = await submitFromForm();
  assert.equal(job.status.state, "succeeded", job.status.error);
  assert.equal(job.sent.render.denoise, "regression");
  assert.equal(job.status.render.denoise, "regression");
  await page.getByLabel("Denoiser").selectOption("");
});

// Adaptive sampling: the form's threshold and min samples carry the contract's limits (render.schema.json) and reach
// the job; the job view tells the mean samples per pixel. A denoised job's viewer offers one click to wipe between
// the denoised image (A, left: the daemon's PNG) and the image as rendered (B, right: the EXR's "noisy" layer).
test("adaptive sampling is set in the form, and a denoised job compares denoised against noisy", async (t) => {
  await page.setViewportSize({ width: 1440, height: 1000 });
  await page.goto(`${baseUrl}/`);
  await page.locator('#connection[data-state="online"]').waitFor();
  const schema = await (await page.request.get(`${baseUrl}/v1/schemas/render.schema.json`)).json();
  let job;

  await t.test("the threshold and min samples take the contract's limits and reach the job", async () => {
    for (const [label, key] of [["Adaptive threshold", "adaptive_threshold"], ["Adaptive min samples", "min_spp"]]) {
      const input = page.getByLabel(label);
      await page.waitForFunction((sel) => document.querySelector(sel).max !== "", `#${await input.getAttribute("id")}`);
      assert.equal(Number(await input.getAttribute("min")), schema.properties[key].minimum, `${label} min`);
      assert.equal(Number(await input.getAttribute("max")), schema.properties[key].maximum, `${label} max`);
    }
    await page.getByRole("tab", { name: "Example" }).click();
    await page.getByLabel("Example scene").selectOption("material");
    await page.getByLabel("Width").fill("48");
    await page.getByLabel("Height").fill("40");
    await page.getByLabel("Samples per pixel").fill("64");
    await page.getByLabel("Integrator").selectOption("path");
    // 0.25: a float holds it exactly (the settings read numbers as floats, and the status shows what they hold).
    await page.getByLabel("Adaptive threshold").fill("0.25");
    await page.getByLabel("Adaptive min samples").fill("8");
    await page.getByLabel("Denoiser").selectOption("regression");
    job = await submitFromForm();
    assert.equal(job.status.state, "succeeded", job.status.error);
    for (const [k, v] of Object.entries({ adaptive_threshold: 0.25, min_spp: 8, denoise: "regression" })) {
      assert.equal(job.sent.render[k], v, `the form sent render.${k}`);
      assert.equal(job.status.render[k], v, `the job renders with ${k} ${v}`);
    }
    for (const label of ["Adaptive threshold", "Adaptive min samples"]) await page.getByLabel(label).fill("");
    await page.getByLabel("Denoiser").selectOption("");
  });

  await t.test("the job view gives the mean samples per pixel of an adaptive job", async () => {
    await page.locator(`#jobs tr[data-id="${job.status.id}"] button.link`).click();
    await page.locator('#viewer[data-source="linear"][data-pass="final"]').waitFor();
    const p = job.status.progress;
    assert.ok(p.samples_done < p.samples_total, `mean ${p.samples_done} of ${p.samples_total} spp`);
    await page.locator("#job-stats", { hasText: `mean ${p.samples_done} of at most ${p.samples_total} per pixel` })
      .waitFor();
  });

  await t.test("one click wipes between the denoised image and the noisy one", async () => {
    const button = page.getByRole("button", { name: "Denoised | noisy" });
    await button.waitFor();
    await page.getByRole("button", { name: "1:1" }).click();
    await button.click();
    await page.locator('#viewer[data-compare="on"]').waitFor();
    assert.equal(await button.getAttribute("aria-pressed"), "true");
    const view = await viewState();
    const pixels = await canvasPixels();
    const split = Math.round(pixels.width / 2);
    const denoised = await pngPixels(`${baseUrl}/v1/jobs/${job.status.id}/result.png`);
    const left = largestDifference(pixels, denoised, view, (cx) => cx < split - 2);
    const right = largestDifference(pixels, denoised, view, (cx) => cx > split + 2);
    assert.ok(left <= 1, `left of the split differs from the denoised PNG by ${left}`);
    assert.ok(right > 1, "right of the split shows the denoised image, not the noisy one");
    // The readout gives B's values from the EXR's noisy layer.
    const exr = await (await page.request.get(`${baseUrl}/v1/jobs/${job.status.id}/result.exr`)).body();
    const noisyR = exrChannel(exr, "noisy.R");
    const box = await page.locator("#viewer canvas").boundingBox();
    await page.mouse.move(box.x + view.x + 30.5, box.y + view.y + 20.5);
    const text = await page.locator("#viewer .readout").textContent();
    const m = text.match(/· B R (\S+)/);
    assert.ok(m, `readout "${text}"`);
    const want = noisyR.get("30 20");
    assert.ok(Math.abs(Number(m[1]) - want) <= 1e-3 * Math.max(1e-3, Math.abs(want)), `B R ${m[1]}, not ${want}`);
    await button.click();
    await page.locator('#viewer[data-compare="off"]').waitFor();
  });

  await t.test("a job without the denoiser offers no such compare", async () => {
    const plain = await renderThroughApi({ kind: "material", material: { type: "lambert" },
      render: { width: 16, height: 16, spp: 4, denoise: "none" } });
    assert.equal(plain.status.state, "succeeded");
    await page.locator(`#jobs tr[data-id="${plain.status.id}"] button.link`).click();
    await page.locator('#viewer[data-source="linear"][data-pass="final"]').waitFor();
    assert.ok(await page.locator("#compare-noisy").isHidden(), "the compare button shows for a job without noisy");
  });
  assert.deepEqual(pageErrors, []);
});

// A glTF whose texture has a valid PNG header and undecodable pixels: accepted (headers are checked at upload),
// then failed when it renders. Returns the job's id.
async function submitBrokenGltf() {
  const png = (() => {
    const chunk = (type, data) => {
      const body = Buffer.concat([Buffer.from(type), data]);
      const len = Buffer.alloc(4);
      len.writeUInt32BE(data.length);
      const crc = Buffer.alloc(4);
      crc.writeUInt32BE(crc32(body));
      return Buffer.concat([len, body, crc]);
    };
    const ihdr = Buffer.from([0, 0, 0, 8, 0, 0, 0, 8, 8, 2, 0, 0, 0]);
    const signature = Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]);
    const idat = chunk("IDAT", Buffer.from("not zlib"));
    return Buffer.concat([signature, chunk("IHDR", ihdr), idat, chunk("IEND", Buffer.alloc(0))]);
  })();
  const buffer = Buffer.alloc(60);
  [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 1].forEach((v, i) => buffer.writeFloatLE(v, 4 * i));
  const gltf = {
    asset: { version: "2.0" },
    scene: 0,
    scenes: [{ nodes: [0] }],
    nodes: [{ mesh: 0 }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0, TEXCOORD_0: 1 }, material: 0 }] }],
    materials: [{ pbrMetallicRoughness: { baseColorTexture: { index: 0 } } }],
    textures: [{ source: 0 }],
    images: [{ uri: "broken.png" }],
    buffers: [{ byteLength: 60, uri: `data:application/octet-stream;base64,${buffer.toString("base64")}` }],
    bufferViews: [
      { buffer: 0, byteOffset: 0, byteLength: 36 },
      { buffer: 0, byteOffset: 36, byteLength: 24 },
    ],
    accessors: [
      { bufferView: 0, componentType: 5126, count: 3, type: "VEC3", min: [0, 0, 0], max: [1, 1, 0] },
      { bufferView: 1, componentType: 5126, count: 3, type: "VEC2" },
    ],
  };
  const form = new FormData();
  const job = { kind: "scene", scene: { gltf: "broken.gltf" }, render: { width: 16, height: 16, spp: 1 } };
  form.append("job", new Blob([JSON.stringify(job)], { type: "application/json" }), "job.json");
  form.append("file", new Blob([JSON.stringify(gltf)], { type: "model/gltf+json" }), "broken.gltf");
  form.append("file", new Blob([png], { type: "image/png" }), "broken.png");
  const res = await page.request.post(`${baseUrl}/v1/jobs`, { multipart: form });
  assert.equal(res.status(), 202, await res.text());
  return (await res.json()).id;
}
function crc32(bytes) {
  let c = ~0;
  for (const b of bytes) {
    c ^= b;
    for (let k = 0; k < 8; ++k) c = (c >>> 1) ^ (0xedb88320 & -(c & 1));
  }
  return ~c >>> 0;
}
// Whether two boxes overlap.
const overlap = (a, b) => a.x < b.x + b.width && b.x < a.x + a.width && a.y < b.y + b.height && b.y < a.y + a.height;
// Errors take their own room: no panel lies under one.
async function assertToastCoversNothing(where) {
  const toast = page.locator(".toast[role=alert]").last();
  await toast.waitFor();
  const box = await toast.boundingBox();
  for (const panel of await page.locator("main .panel").all()) {
    const p = await panel.boundingBox();
    assert.ok(!overlap(box, p), `${where}: the error ${JSON.stringify(box)} covers a panel ${JSON.stringify(p)}`);
  }
  await toast.getByRole("button", { name: "Dismiss" }).click();
}

// A failed job says why where it is seen (its row, the top of its view); errors never cover the page; at a phone's
// width (390 px) every row's progress and buttons are on the screen.
test("failures are shown, errors cover nothing, and the queue fits 390 px", async (t) => {
  await page.setViewportSize({ width: 1440, height: 1000 });
  await page.goto(`${baseUrl}/`);
  const failed = await submitBrokenGltf();
  const status = (await finished(failed)).status;
  assert.equal(status.state, "failed");
  assert.match(status.error, /cannot be decoded/);

  await t.test("the reason is in the queue row and heads the job view; its bad input is not offered Requeue", async () => {
    const row = page.locator(`#jobs tr[data-id="${failed}"]`);
    await row.locator(".reason", { hasText: "cannot be decoded" }).waitFor();
    assert.ok(await row.locator(".reason").isVisible());
    // Called by the file it renders; its input is at fault, so running it again would fail the same way.
    assert.equal(await row.locator("button.link").textContent(), "broken.gltf");
    assert.deepEqual(status.actions, ["delete"]);
    assert.ok(await row.getByRole("button", { name: /^Requeue job/ }).isDisabled(), "no Requeue in the row");
    assert.ok(await row.getByRole("button", { name: /^Delete job/ }).isEnabled(), "Delete in the row");
    await row.locator("button.link").click();
    const failure = page.locator("#job-failure");
    await failure.waitFor();
    assert.match(await failure.textContent(), /Failed.*cannot be decoded/s);
    // It comes first: above the image and the statistics.
    const [f, v] = [await failure.boundingBox(), await page.locator("#viewer").boundingBox()];
    assert.ok(f.y + f.height <= v.y, "the failure is above the image");
    assert.ok(await page.locator('#job-body [data-action="requeue"]').isDisabled(), "no Requeue in the job view");
  });

  const refuse = async () => {
    await page.getByRole("tab", { name: "JSON" }).click();
    await page.getByLabel("Job document").fill('{"kind": "scene", "render": {"width": 0}}');
    await page.getByRole("button", { name: "Submit job" }).click();
  };
  await t.test("an error covers no panel (1440 px)", async () => {
    await refuse();
    await assertToastCoversNothing("1440 px");
  });

  await t.test("at 390 px the queue's progress and actions fit, and errors cover nothing", async () => {
    await page.setViewportSize({ width: 390, height: 844 });
    await page.waitForTimeout(200);
    const wrap = page.locator(".table-wrap");
    const [scroll, client] = await wrap.evaluate((e) => [e.scrollWidth, e.clientWidth]);
    assert.ok(scroll <= client, `the queue scrolls sideways: ${scroll} px in ${client}`);
    const rows = await page.locator("#jobs tr").all();
    assert.ok(rows.length >= 3);
    for (const row of rows) {
      for (const part of [row.locator(".progress"), ...(await row.locator(".actions button").all())]) {
        const b = await part.boundingBox();
        const what = (await part.getAttribute("class")) || "button";
        assert.ok(b && b.x >= 0 && b.x + b.width <= 390, `a row's ${what} at ${JSON.stringify(b)}`);
      }
    }
    await page.locator("#submit-form").scrollIntoViewIfNeeded();
    await refuse();
    await assertToastCoversNothing("390 px");
    await page.getByRole("tab", { name: "Example" }).click();
    await page.setViewportSize({ width: 1440, height: 1000 });
  });
  assert.deepEqual(pageErrors, []);
});

// One triangle facing +z in a .gltf with its buffer inline (a data: URI), and a 8x4 Radiance .hdr of radiance 1.
function triangleGltf() {
  const buffer = Buffer.alloc(36);
  [-1, -1, 0, 1, -1, 0, 0, 1, 0].forEach((v, i) => buffer.writeFloatLE(v, 4 * i));
  return {
    asset: { version: "2.0" },
    scene: 0,
    scenes: [{ nodes: [0] }],
    nodes: [{ mesh: 0 }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0 } }] }],
    buffers: [{ byteLength: 36, uri: `data:application/octet-stream;base64,${buffer.toString("base64")}` }],
    bufferViews: [{ buffer: 0, byteOffset: 0, byteLength: 36 }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: "VEC3", min: [-1, -1, 0], max: [1, 1, 0] }],
  };
}
function flatHdr(width = 8, height = 4) {
  const header = Buffer.from(`#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y ${height} +X ${width}\n`);
  // Uncompressed scan lines (a width below 8 cannot be run-length encoded; 8 is read flat when it is not marked).
  const pixels = Buffer.alloc(width * height * 4);
  for (let i = 0; i < width * height; ++i) pixels.set([128, 128, 128, 129], 4 * i);
  return Buffer.concat([header, pixels]);
}

// Item 11 and the rest of item 10: every render setting is in the form and reaches the job; a job's document is
// what was submitted; Duplicate fills the form with it and Re-render submits it again (the same image: sampling is
// deterministic); an environment map goes along from the glTF tab; a job cancelled after a pass shows and downloads
// the image of its last pass.
test("documents are seen and reused, every setting is in the form, and a cancelled job keeps its image", async (t) => {
  await page.setViewportSize({ width: 1440, height: 1000 });
  await page.goto(`${baseUrl}/`);
  await page.locator('#connection[data-state="online"]').waitFor();
  let first;

  await t.test("every render setting in the form reaches the job", async () => {
    await page.getByRole("tab", { name: "Example" }).click();
    await page.getByLabel("Example scene").selectOption("material");
    await page.getByLabel("Name", { exact: true }).fill("every setting");
    await page.getByLabel("Width").fill("24");
    await page.getByLabel("Height").fill("20");
    await page.getByLabel("Samples per pixel").fill("8");
    await page.getByLabel("Max depth").fill("3");
    await page.getByLabel("Seed").fill("7");
    await page.getByLabel("Noise target").fill("0.5");
    await page.getByLabel("Sampler").selectOption("independent");
    await page.getByLabel("Exposure (stops)").fill("1.5");
    await page.getByLabel("Tone curve").selectOption("aces");
    await page.getByLabel("EXR precision").selectOption("float");
    await page.getByLabel("Integrator").selectOption("path");
    await page.getByLabel("EXR", { exact: true }).uncheck();
    first = await submitFromForm();
    assert.equal(first.status.state, "succeeded", first.status.error);
    const want = { width: 24, height: 20, spp: 8, max_depth: 3, seed: 7, noise_target: 0.5, sampler: "independent",
      exposure_ev: 1.5, tonemap: "aces", exr_precision: "float", integrator: "path" };
    for (const [k, v] of Object.entries(want)) {
      assert.equal(first.sent.render[k], v, `the form sent render.${k}`);
      assert.equal(first.status.render[k], v, `the job renders with ${k} ${v}`);
    }
    assert.deepEqual(first.sent.outputs, ["png"]);
    assert.deepEqual(first.status.outputs, ["png"]);
    assert.equal(first.status.name, "every setting");
    await page.getByLabel("EXR", { exact: true }).check();
  });

  await t.test("the job's document is the one submitted", async () => {
    const res = await page.request.get(`${baseUrl}/v1/jobs/${first.status.id}/document`);
    assert.equal(res.status(), 200);
    assert.deepEqual(await res.json(), first.sent);
  });

  await t.test("Re-render submits the document again: the same image", async () => {
    await page.locator(`#jobs tr[data-id="${first.status.id}"] button.link`).click();
    await page.locator('#job-state[data-state="succeeded"]').waitFor();
    await page.waitForFunction(() => !document.querySelector("#rerender").disabled);
    await page.getByRole("button", { name: "Re-render" }).click();
    await page.waitForFunction((id) => {
      const t = document.querySelector("#job-title")?.title;
      return t && t !== id;
    }, first.status.id);
    const again = await finished(await page.locator("#job-title").getAttribute("title"));
    assert.equal(again.status.state, "succeeded");
    assert.equal(again.status.name, "every setting");
    assert.deepEqual(again.status.render, first.status.render);
    assert.ok(again.png.equals(first.png), "the re-render's PNG equals the first one's");
  });

  await t.test("Duplicate fills the form with the document", async () => {
    await page.goto(`${baseUrl}/`);
    await page.locator(`#jobs tr[data-id="${first.status.id}"] button.link`).click();
    await page.locator('#job-state[data-state="succeeded"]').waitFor();
    await page.getByRole("button", { name: "Duplicate" }).click();
    await page.locator('#tab-json[aria-selected="true"]').waitFor();
    assert.deepEqual(JSON.parse(await page.getByLabel("Job document").inputValue()), first.sent);
    assert.equal(await page.getByLabel("Name", { exact: true }).inputValue(), "every setting");
    assert.equal(await page.getByLabel("Max depth").inputValue(), "3");
    assert.equal(await page.getByLabel("Seed").inputValue(), "7");
    assert.equal(await page.getByLabel("Tone curve").inputValue(), "aces");
    assert.ok(!(await page.getByLabel("EXR", { exact: true }).isChecked()), "the outputs as the job had them");
    // Changed and submitted, it is a new job with the change.
    const doc = JSON.parse(await page.getByLabel("Job document").inputValue());
    doc.render.seed = 8;
    doc.name = "duplicated";
    await page.getByLabel("Job document").fill(JSON.stringify(doc));
    const copy = await submitFromForm();
    assert.equal(copy.status.state, "succeeded", copy.status.error);
    assert.equal(copy.status.name, "duplicated");
    assert.equal(copy.status.render.seed, 8);
    assert.equal(copy.status.render.max_depth, 3);
  });

  await t.test("an environment map goes along from the glTF tab", async () => {
    await page.goto(`${baseUrl}/`);
    await page.getByRole("tab", { name: "glTF" }).click();
    await page.getByLabel("glTF files").setInputFiles({
      name: "triangle.gltf", mimeType: "model/gltf+json", buffer: Buffer.from(JSON.stringify(triangleGltf())),
    });
    await page.getByLabel("Environment map").setInputFiles({
      name: "sky.hdr", mimeType: "image/vnd.radiance", buffer: flatHdr(),
    });
    await page.getByLabel("Environment intensity").fill("2");
    await page.getByLabel("Width").fill("16");
    await page.getByLabel("Height").fill("16");
    await page.getByLabel("Samples per pixel").fill("2");
    const res = await submitResponse();
    assert.equal(res.status(), 202, await res.text());
    const done = await finished((await res.json()).id);
    assert.equal(done.status.state, "succeeded", done.status.error);
    assert.equal(done.status.name, "triangle.gltf");
    const doc = await (await page.request.get(`${baseUrl}/v1/jobs/${done.status.id}/document`)).json();
    const map = doc.scene.environment?.map;
    assert.match(map || "", /^[0-9a-f]{64}$/, JSON.stringify(doc.scene));
    assert.equal(doc.scene.environment.intensity, 2);
    const asset = await (await page.request.get(`${baseUrl}/v1/assets/${map}`)).json();
    assert.equal(asset.kind, "environment");
    await page.getByRole("tab", { name: "Example" }).click();
  });

  await t.test("a job cancelled after a pass shows and downloads the image of its last pass", async () => {
    const job = structuredClone(JSON.parse(fs.readFileSync(path.join(repo, "proto/examples/cornell.json"), "utf8")));
    job.render = { ...job.render, width: 96, height: 64, spp: 65536 };
    const res = await page.request.post(`${baseUrl}/v1/jobs`, { data: job });
    assert.equal(res.status(), 202);
    const id = (await res.json()).id;
    for (const deadline = Date.now() + 60000; ; ) {
      const s = await (await page.request.get(`${baseUrl}/v1/jobs/${id}`)).json();
      if (s.progress.passes >= 2) break;
      assert.ok(Date.now() < deadline, `no second pass: ${JSON.stringify(s)}`);
      await page.waitForTimeout(100);
    }
    await page.goto(`${baseUrl}/`);
    await page.locator(`#jobs tr[data-id="${id}"] button.link`).click();
    await page.locator('#job-body [data-action="cancel"]:not([disabled])').click();
    await page.locator('#job-state[data-state="cancelled"]').waitFor();
    await page.locator('#viewer[data-pass="partial"]').waitFor();
    assert.match(await page.locator("#preview-caption").textContent(), /partial: cancelled/);
    await page.waitForFunction(() => !document.querySelector("#download-png").disabled);
    const [download] = await Promise.all([page.waitForEvent("download"), page.locator("#download-png").click()]);
    const bytes = fs.readFileSync(await download.path());
    assert.deepEqual([...bytes.subarray(0, 8)], [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a], "PNG signature");
    assert.equal(bytes.readUInt32BE(16), 96);
    assert.equal(bytes.readUInt32BE(20), 64);
    assert.match(download.suggestedFilename(), /-partial\.png$/);
    await page.waitForFunction(() => !document.querySelector("#download-exr").disabled);  // the EXR too
  });
  assert.deepEqual(pageErrors, []);
});

// A frame range from the form: the animated spinning cube's frames 1 to 24 from the glTF tab; while it renders the
// viewer shows its latest frame; the strip fills with thumbnails of the finished frames, a window of 12 that pages;
// a click shows a frame as a finished image with its downloads; Play steps through the frames at the job's fps and
// the scrubber picks one.
test("a frame range is submitted from the form, its strip fills, and it plays", async (t) => {
  await page.setViewportSize({ width: 1440, height: 1000 });
  await page.goto(`${baseUrl}/`);
  await page.locator('#connection[data-state="online"]').waitFor();
  const frameOf = async () => page.locator("#viewer").getAttribute("data-frame");
  let id;

  await step(t, "the form's frame fields take the contract's limits and submit a range", async () => {
    const schema = await (await page.request.get(`${baseUrl}/v1/schemas/render.schema.json`)).json();
    const limits = schema.properties.frames.properties;
    await page.waitForFunction((min) => document.querySelector("#frames-step").min === String(min), limits.step.minimum);
    assert.equal(await page.getByLabel("First frame").getAttribute("min"), String(limits.start.minimum));
    assert.equal(await page.getByLabel("Last frame").getAttribute("max"), String(limits.end.maximum));
    assert.equal(await page.getByLabel("Frames per second").getAttribute("max"), String(schema.properties.fps.maximum));
    await page.getByRole("tab", { name: "glTF" }).click();
    await page.getByLabel("glTF files").setInputFiles({
      name: "SpinningCube.glb", mimeType: "model/gltf-binary",
      buffer: fs.readFileSync(path.join(repo, "examples/spinning_cube/SpinningCube.glb")),
    });
    await page.getByLabel("Width").fill("64");
    await page.getByLabel("Height").fill("36");
    await page.getByLabel("Samples per pixel").fill("2");
    await page.getByLabel("First frame").fill("1");
    await page.getByLabel("Last frame").fill("24");
    await page.getByLabel("Frames per second").fill("12");
    const res = await submitResponse();
    assert.equal(res.status(), 202, await res.text());
    id = (await res.json()).id;
    const doc = await (await page.request.get(`${baseUrl}/v1/jobs/${id}/document`)).json();
    assert.deepEqual(doc.render.frames, { start: 1, end: 24 });
    assert.equal(doc.render.fps, 12);
    await page.locator(`#job-title[title="${id}"]`).waitFor();
  });

  await step(t, "while it renders, the viewer shows its latest frame and the strip fills", async () => {
    await page.locator("#frames-panel").waitFor();
    await page.locator('#frames-strip [data-state="done"] img[src^="blob:"]').first().waitFor();
    const running = await (await page.request.get(`${baseUrl}/v1/jobs/${id}`)).json();
    if (running.state === "running") {
      await page.locator("#preview-placeholder").waitFor({ state: "hidden" });
      assert.match(await page.locator("#preview-caption").textContent(), /latest finished frame|Frame \d+/);
    }
    const done = await finished(id);
    assert.equal(done.status.state, "succeeded", done.status.error);
    await page.waitForFunction(() => /^24 of 24 frames done/.test(document.querySelector("#frames-counts").textContent));
    // A window of the range, following the latest frame, which shows as a finished image.
    await page.locator('#viewer[data-frame="24"][data-pass="final"][data-source="linear"]').waitFor();
    const cells = page.locator("#frames-strip .frame-thumb");
    assert.equal(await cells.count(), 12, "the strip shows a window of 12 frames, not the whole range");
    assert.equal(await cells.last().getAttribute("data-frame"), "24");
    assert.equal(await cells.last().getAttribute("aria-pressed"), "true");
    const thumbs = () => page.evaluate(() =>
      [...document.querySelectorAll("#frames-strip img")].map((i) => (i.complete ? i.naturalWidth : "loading")));
    for (const deadline = Date.now() + 20000; ; ) {
      const widths = await thumbs();
      if (widths.length === 12 && widths.every((w) => w === 64)) break;
      assert.ok(Date.now() < deadline, `every frame of the window shows its 64-pixel-wide PNG: ${widths}`);
      await page.waitForTimeout(100);
    }
    assert.equal(await page.locator("#frames-fps").textContent(), "12 fps");
  });

  await step(t, "the strip pages, and a click shows a frame as a finished image with its downloads", async () => {
    await page.getByRole("button", { name: "Earlier frames" }).click();
    await page.waitForFunction(() => document.querySelector("#frames-strip .frame-thumb").dataset.frame === "1");
    assert.ok(await page.getByRole("button", { name: "Earlier frames" }).isDisabled());
    await page.locator('#frames-strip [data-frame="3"]').click();
    await page.locator('#viewer[data-frame="3"][data-pass="final"][data-source="linear"]').waitFor();
    assert.equal(await page.locator("#preview-caption").textContent(), "Frame 3 · final");
    const [download] = await Promise.all([page.waitForEvent("download"), page.locator("#frame-download-png").click()]);
    const want = await (await page.request.get(`${baseUrl}/v1/jobs/${id}/frames/3/result.png`)).body();
    assert.ok(fs.readFileSync(await download.path()).equals(want), "the downloaded PNG is frame 3's");
    const [exr] = await Promise.all([page.waitForEvent("download"), page.locator("#frame-download-exr").click()]);
    assert.match(exr.suggestedFilename(), /frame-3\.exr$/);
  });

  await step(t, "Play advances the frame shown at the job's fps, Pause stops it, the scrubber picks one", async () => {
    await page.getByRole("button", { name: "Play frames" }).click();
    // The frames shown, in order: from the one picked, one after the other.
    const seen = ["3"];
    for (const deadline = Date.now() + 15000; seen.length < 5; ) {
      const f = await frameOf();
      if (f !== seen[seen.length - 1]) seen.push(f);
      assert.ok(Date.now() < deadline, `the player showed only frames ${seen}`);
      await page.waitForTimeout(20);
    }
    assert.deepEqual(seen.slice(0, 4), ["3", "4", "5", "6"], "the player steps frame by frame");
    await page.getByRole("button", { name: "Pause frames" }).click();
    const stopped = await frameOf();
    await page.waitForTimeout(400);
    assert.equal(await frameOf(), stopped, "paused, the frame stays");
    assert.equal(await page.locator("#frames-scrubber").inputValue(), String(Number(stopped) - 1));
    await page.locator("#frames-scrubber").fill("9");
    await page.locator('#viewer[data-frame="10"]').waitFor();
    await page.waitForFunction(() => document.querySelector('#frames-strip [data-frame="10"]')?.getAttribute("aria-pressed") === "true");
    await page.getByRole("tab", { name: "Example" }).click();
    await page.getByLabel("First frame").fill("");
    await page.getByLabel("Last frame").fill("");
    await page.getByLabel("Frames per second").fill("");
  });
  assert.deepEqual(pageErrors, []);
});

test("the web client honours Retry-After from an overloaded server", async () => {
  const { retryAfterMs } = await import(path.join(repo, "clients/web/api.js"));
  assert.equal(retryAfterMs("3"), 3000);
  assert.equal(retryAfterMs("Wed, 21 Oct 2015 07:28:30 GMT", Date.parse("Wed, 21 Oct 2015 07:28:00 GMT")), 30000);
  assert.equal(retryAfterMs("soon"), null);
  assert.equal(retryAfterMs(null), null);
  assert.equal(retryAfterMs("86400"), 600000);

  // The job list answers 503 with Retry-After: 3; the page polls it every 1.5 s otherwise.
  const seen = [];
  const handler = (route) => {
    seen.push(Date.now());
    return route.fulfill({
      status: 503,
      headers: { "Retry-After": "3", "Content-Type": "application/problem+json" },
      body: JSON.stringify({ type: "about:blank", title: "Service Unavailable", status: 503, detail: "busy" }),
    });
  };
  await page.route(/\/v1\/jobs\?limit=/, handler);
  try {
    await page.waitForTimeout(7500);
  } finally {
    await page.unroute(/\/v1\/jobs\?limit=/, handler);
  }
  assert.ok(seen.length >= 2, `the page asked for the job list ${seen.length} times in 7.5 s`);
  const gaps = seen.slice(1).map((t, i) => t - seen[i]);
  for (const gap of gaps) assert.ok(gap >= 2500, `the page asked again after ${gap} ms, not the 3 s it was told`);
  // Answered again, the page goes back to its own pace and shows the server online.
  await page.locator('#connection[data-state="online"]').waitFor();
});

// Emulates the tab going to the background (another tab in front, a minimised window) or coming back: what
// document.hidden says, and the event the page listens to.
async function setHidden(p, hidden) {
  await p.evaluate((h) => {
    Object.defineProperty(document, "hidden", { configurable: true, get: () => h });
    Object.defineProperty(document, "visibilityState", { configurable: true, get: () => (h ? "hidden" : "visible") });
    document.dispatchEvent(new Event("visibilitychange"));
  }, hidden);
}
// Clicks "Submit job" on page `p` and returns the POST's request and its response's JSON (the job), after a 202.
async function submitAccepted(p) {
  const [res] = await Promise.all([
    p.waitForResponse((r) => r.request().method() === "POST" && new URL(r.url()).pathname === "/v1/jobs"),
    p.getByRole("button", { name: "Submit job" }).click(),
  ]);
  assert.equal(res.status(), 202, await res.text());
  return { sent: JSON.parse(res.request().postData() || "null"), job: await res.json() };
}
const nameField = () => page.getByLabel("Name", { exact: true });
// What get() returns once it equals `want`, or within `ms` its last value, which then fails the assertion: a
// readable failure for what the page changes a moment after an action (a field cleared after the answer, a title).
async function settles(get, want, message, ms = 10000) {
  let got;
  for (const deadline = Date.now() + ms; ; await new Promise((r) => setTimeout(r, 100))) {
    got = await get();
    if (JSON.stringify(got) === JSON.stringify(want) || Date.now() > deadline) break;
  }
  assert.deepEqual(got, want, message);
}
// The labels of the material form's controls as the user sees them: shown first, then those under "Advanced".
async function materialLabels() {
  return page.evaluate(() => {
    const form = document.querySelector("#material-params .material-params");
    const label = (row) => row.querySelector("label").textContent;
    return {
      shown: [...form.querySelectorAll(":scope > [data-param]")].map(label),
      advanced: [...form.querySelectorAll(":scope > details > [data-param]")].map(label),
      params: [...form.querySelectorAll("[data-param]")].map((r) => r.dataset.param),
      open: form.querySelector(":scope > details")?.open ?? null,
      summary: form.querySelector(":scope > details > summary")?.textContent ?? null,
    };
  });
}

test("what users reported: the name, the error banner, the material form and the smaller things", async (t) => {
  await page.setViewportSize({ width: 1440, height: 1000 });
  await page.goto(`${baseUrl}/`);
  await page.locator('#connection[data-state="online"]').waitFor();
  const small = async () => {
    await page.getByLabel("Width").fill("16");
    await page.getByLabel("Height").fill("16");
    await page.getByLabel("Samples per pixel").fill("1");
  };

  await t.test("the Name is cleared after a submit and on a change of tab, and kept until then", async () => {
    await page.getByRole("tab", { name: "Example" }).click();
    await page.getByLabel("Example scene").selectOption("material");
    await small();
    await nameField().fill("first job");
    const first = await submitAccepted(page);
    assert.equal(first.sent.name, "first job");
    await settles(() => nameField().inputValue(), "", "the Name after a submit that succeeded");
    // The report: an upload after that was queued under the previous job's name. It is called by its file.
    await page.getByRole("tab", { name: "glTF" }).click();
    await page.getByLabel("glTF files").setInputFiles({
      name: "triangle.gltf", mimeType: "model/gltf+json", buffer: Buffer.from(JSON.stringify(triangleGltf())),
    });
    await small();
    const upload = await submitAccepted(page);
    assert.equal(upload.job.name, "triangle.gltf");
    // A name typed for this submission is what it is called; typed and then the tab changed, it is gone.
    await nameField().fill("my triangle");
    const named = await submitAccepted(page);
    assert.equal(named.job.name, "my triangle");
    assert.equal(await nameField().inputValue(), "");
    // (The JSON tab sends its document as it is: the render settings and the name are disabled there.)
    for (const tab of ["Material", "glTF", "JSON", "Example"]) {
      if (await nameField().isEnabled()) await nameField().fill(`typed before ${tab}`);
      await page.getByRole("tab", { name: tab }).click();
      assert.equal(await nameField().inputValue(), "", `the name is cleared on the way to the ${tab} tab`);
    }
    // Picking the tab already open changes nothing; the arrow keys change tabs as clicks do.
    await nameField().fill("kept");
    await page.getByRole("tab", { name: "Example" }).click();
    assert.equal(await nameField().inputValue(), "kept");
    await page.getByRole("tab", { name: "Example" }).press("ArrowRight");
    assert.equal(await nameField().inputValue(), "");
    await page.getByRole("tab", { name: "Example" }).click();
  });

  await t.test("one error banner at a time, gone after a submit succeeds or when dismissed", async () => {
    await page.getByRole("tab", { name: "JSON" }).click();
    const banners = page.locator("#toasts .toast");
    for (const key of ["width", "height", "spp"]) {
      await page.getByLabel("Job document").fill(`{"kind": "material", "material": {"type": "lambert"}, "render": {"${key}": 0}}`);
      const res = await submitResponse();
      assert.equal(res.status(), 422);
      await banners.filter({ hasText: `/render/${key}` }).waitFor();
      assert.equal(await banners.count(), 1, `after the refused ${key}: ${await banners.allTextContents()}`);
    }
    const doc = { kind: "material", material: { type: "lambert" }, render: { width: 8, height: 8, spp: 1 } };
    await page.getByLabel("Job document").fill(JSON.stringify(doc));
    await submitAccepted(page);
    await banners.first().waitFor({ state: "detached" });
    assert.equal(await banners.count(), 0, "a submit that succeeded leaves no error about an earlier one");
    await page.getByLabel("Job document").fill("{not json");
    await page.getByRole("button", { name: "Submit job" }).click();
    await banners.first().waitFor();
    await banners.first().getByRole("button", { name: "Dismiss" }).click();
    assert.equal(await banners.count(), 0);
    await page.getByRole("tab", { name: "Example" }).click();
  });

  await t.test("the material form shows the common parameters first and folds the rest under Advanced", async () => {
    const { PRIMARY_PARAMETERS, NOT_ON_PREVIEW_STAGE } = await import(path.join(repo, "clients/web/materials.js"));
    const materials = (await (await page.request.get(`${baseUrl}/v1/materials`)).json()).materials.filter(
      (m) => !NOT_ON_PREVIEW_STAGE.includes(m.type),
    );
    await page.getByRole("tab", { name: "Material" }).click();
    const pick = async (type) => {
      await page.getByLabel("Material model").selectOption(type);
      await page.locator(`#material-params [data-param]`).first().waitFor({ state: "attached" });
      return materialLabels();
    };
    // What was reported: a conductor's roughness was the seventh control, under Alpha x, Alpha y, Eta and K.
    const conductor = await pick("conductor");
    assert.deepEqual(conductor.shown, ["Metal", "Roughness"]);
    assert.deepEqual(conductor.advanced.slice(0, 5), ["Distribution", "Alpha x", "Alpha y", "Eta", "K"]);
    assert.equal(conductor.open, false, "Advanced starts folded");
    assert.match(conductor.summary, /^Advanced/);
    assert.ok(await page.locator('[data-param="alpha_x"]').isHidden(), "alpha_x is out of the way");
    assert.ok(await page.locator('[data-param="roughness"] input[type="number"]').isVisible());
    await page.locator("#material-params summary").click();
    assert.ok(await page.locator('[data-param="alpha_x"]').isVisible(), "opened, Advanced shows alpha_x");
    const pbr = await pick("gltf_pbr");
    assert.deepEqual(pbr.shown.slice(0, 4), ["Base color", "Roughness", "Metallic", "Ior"]);
    assert.deepEqual((await pick("lambert")).shown, ["Albedo"]);
    // Every model by the one rule: the common parameters in their order, the rest in the schema's order, folded.
    for (const model of materials) {
      const form = await pick(model.type);
      const names = model.parameters.map((p) => p.name);
      const rank = (n) => PRIMARY_PARAMETERS.indexOf(n);
      const common = names.filter((n) => rank(n) >= 0).sort((a, b) => rank(a) - rank(b));
      assert.ok(common.length, `${model.type} shows at least one control`);
      assert.deepEqual(form.params, [...common, ...names.filter((n) => rank(n) < 0)], model.type);
      assert.equal(form.shown.length, common.length, model.type);
    }
    await page.getByRole("tab", { name: "Example" }).click();
  });

  await t.test("Fit does not enlarge a small render beyond 1:1, and still shrinks a large one", async () => {
    const material = { type: "lambert", albedo: [0.8, 0.5, 0.2] };
    const submit = async (render) =>
      (await (await page.request.post(`${baseUrl}/v1/jobs`, { data: { kind: "material", material, render } })).json()).id;
    const tiny = await submit({ width: 40, height: 30, spp: 2 });
    const wide = await submit({ width: 2400, height: 40, spp: 1 });
    for (const id of [tiny, wide]) assert.equal((await finished(id)).status.state, "succeeded");
    // The drawn image's size on the screen, in CSS pixels: the box of the canvas's painted (opaque) pixels.
    const drawn = () =>
      page.evaluate(() => {
        const c = document.querySelector("#viewer canvas");
        const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
        let [x0, y0, x1, y1] = [Infinity, Infinity, -1, -1];
        for (let y = 0; y < c.height; ++y) {
          for (let x = 0; x < c.width; ++x) {
            if (d[4 * (y * c.width + x) + 3] === 0) continue;
            [x0, y0, x1, y1] = [Math.min(x0, x), Math.min(y0, y), Math.max(x1, x), Math.max(y1, y)];
          }
        }
        const dpr = window.devicePixelRatio || 1;
        return { width: (x1 - x0 + 1) / dpr, height: (y1 - y0 + 1) / dpr, frame: c.clientWidth };
      });
    await page.goto(`${baseUrl}/`);
    await page.locator(`#jobs tr[data-id="${tiny}"] button.link`).click();
    await page.locator('#viewer[data-pass="final"]').waitFor();
    await page.getByRole("button", { name: "Fit", exact: true }).click();
    const size = await drawn();
    assert.ok(size.frame > 200, `the frame is ${size.frame} px wide`);
    assert.deepEqual([size.width, size.height], [40, 30], `a 40 x 30 render at Fit is drawn ${JSON.stringify(size)}`);
    assert.match(await page.locator("#viewer .zoom").textContent(), /^100% \(fit\)/);
    // Zooming in is how it gets larger.
    await page.getByRole("button", { name: "Zoom in" }).click();
    assert.deepEqual(Object.values(await drawn()).slice(0, 2), [80, 60]);
    await page.locator(`#jobs tr[data-id="${wide}"] button.link`).click();
    await page.locator('#viewer[data-pass="final"]').waitFor();
    await page.getByRole("button", { name: "Fit", exact: true }).click();
    const fitted = await drawn();
    const zoom = Number(await page.locator("#viewer").getAttribute("data-zoom"));
    assert.ok(zoom < 1, `2400 px wide at Fit: zoom ${zoom}`);
    assert.ok(fitted.width <= fitted.frame && Math.abs(fitted.width - 2400 * zoom) <= 2, JSON.stringify(fitted));
  });

  await t.test("the delete confirmation names the job, with its short id", async () => {
    const res = await page.request.post(`${baseUrl}/v1/jobs`, {
      data: { kind: "material", name: "Teapot draft", material: { type: "lambert" }, render: { width: 8, height: 8, spp: 1 } },
    });
    const id = (await res.json()).id;
    await finished(id);
    await page.goto(`${baseUrl}/`);
    const row = page.locator(`#jobs tr[data-id="${id}"]`);
    await row.getByRole("button", { name: /^Delete job/ }).click();
    await page.locator("#confirm[open]").waitFor();
    const text = await page.locator("#confirm-text").textContent();
    if (!text.includes("Teapot draft")) await page.locator("#confirm").getByRole("button", { name: "Keep" }).click();
    assert.equal(text, `Job “Teapot draft” (${id.slice(0, 8)}) and its images will be deleted. This cannot be undone.`);
    await page.locator("#confirm").getByRole("button", { name: "Delete" }).click();
    await row.waitFor({ state: "detached" });
    assert.match(await page.locator("#notice").textContent(), /Teapot draft/);
  });

  await t.test("the page has an icon, and /favicon.ico answers with it", async () => {
    const ico = await page.request.get(`${baseUrl}/favicon.ico`);
    assert.equal(ico.status(), 200, "GET /favicon.ico");
    assert.equal(ico.headers()["content-type"], "image/svg+xml");
    assert.ok((await ico.body()).length < 1024, "a tiny icon");
    assert.equal(await page.locator('link[rel="icon"]').count(), 1, "index.html links an icon");
    const href = await page.locator('link[rel="icon"]').getAttribute("href");
    const linked = await page.request.get(new URL(href, `${baseUrl}/`).href);
    assert.equal(linked.status(), 200);
    assert.equal(linked.headers()["content-type"], "image/svg+xml");
    // It is an image the browser draws.
    const drawn = await page.evaluate(async (u) => {
      const img = new Image();
      img.src = u;
      await img.decode();
      return img.naturalWidth > 0;
    }, `${baseUrl}/favicon.ico`);
    assert.ok(drawn);
  });

  await t.test("the Example tab lists every job of proto/examples, as the file holds it", async () => {
    const files = fs.readdirSync(path.join(repo, "proto/examples")).filter((f) => f.endsWith(".json")).sort();
    assert.ok(files.length >= 4, `${files}`);
    await page.goto(`${baseUrl}/`);
    await page.getByRole("tab", { name: "Example" }).click();
    const select = page.getByLabel("Example scene");
    const listed = () => select.locator("option").evaluateAll((os) => os.map((o) => o.value));
    // Each file by its name, and the client's own material preview after them.
    const want = [...files.map((f) => f.replace(/\.json$/, "")), "material"];
    await settles(listed, want, "the Example tab's list");
    const titles = await select.locator("option").allTextContents();
    assert.ok(titles.includes("Room lit through a gap (scene)"), `${titles}`);
    for (const f of ["prism.json", "room_gap.json"]) {
      const file = JSON.parse(fs.readFileSync(path.join(repo, "proto/examples", f), "utf8"));
      await select.selectOption(f.replace(/\.json$/, ""));
      // The example's own settings fill the form (its integrator, say).
      assert.equal(await page.getByLabel("Integrator").inputValue(), file.render.integrator || "path");
      await small();
      const { sent, job } = await submitAccepted(page);
      assert.deepEqual(sent.scene, file.scene, `${f}: the scene sent is the file's`);
      assert.equal(sent.render.integrator, file.render.integrator);
      await page.request.post(`${baseUrl}/v1/jobs/${job.id}/cancel`);
    }
  });

  await t.test("a job that ends while the tab is hidden shows in the title, and notifies when asked to", async () => {
    // A tab of its own: the spy on notifications stays in it.
    await context.grantPermissions(["notifications"], { origin: baseUrl });
    const tab = await context.newPage();
    tab.setDefaultTimeout(30000);
    tab.on("pageerror", (e) => pageErrors.push(`page error (second tab): ${e.message}`));
    try {
      await tab.addInitScript(() => {
        const Real = window.Notification;
        window.__shown = [];
        window.__asked = 0;
        const ask = Real.requestPermission.bind(Real);
        Real.requestPermission = (...a) => (++window.__asked, ask(...a));
        window.Notification = new Proxy(Real, {
          construct(target, args) {
            window.__shown.push(args[0]);
            return Reflect.construct(target, args);
          },
          get: (target, key) => Reflect.get(target, key),
        });
      });
      await tab.goto(`${baseUrl}/`);
      await tab.locator('#connection[data-state="online"]').waitFor();
      assert.equal(await tab.title(), "tessera");
      assert.equal(await tab.evaluate(() => window.__asked), 0, "nothing is asked when the page loads");
      await tab.getByRole("tab", { name: "Example" }).click();
      await tab.getByLabel("Example scene").selectOption("material");
      await tab.getByLabel("Width").fill("32");
      await tab.getByLabel("Height").fill("32");
      await tab.getByLabel("Samples per pixel").fill("65536");
      await tab.getByLabel("Time limit (s)").fill("2");
      const title = () => tab.title();

      // The title: one job, followed in the job view (a submitted job is selected), ends while the tab is hidden. The
      // tab is hidden before the submission: a job of 2 s may end before a loaded machine runs the next step.
      await tab.getByLabel("Name", { exact: true }).fill("one");
      await setHidden(tab, true);
      const one = (await submitAccepted(tab)).job;
      assert.equal(await title(), "tessera", "nothing has ended yet");
      assert.equal((await finished(one.id)).status.state, "succeeded");
      await settles(title, "✓ done: one — tessera", "the title after the job ended in the background");
      await setHidden(tab, false);
      assert.equal(await title(), "tessera", "seen again, the title is the page's own");
      assert.deepEqual(await tab.evaluate(() => window.__shown), [], "no notification unless asked for");

      // Notify me: two jobs, the first followed as submitted here, the second in the job view too.
      const notify = tab.getByLabel("Notify me");
      assert.equal(await notify.count(), 1, "a Notify me box");
      await notify.check();
      assert.ok(await notify.isChecked(), "permission granted: the box stays ticked");
      // The job list's answers arrive 1.5 s late, after the followed job's stream has told its end: a late answer
      // shows that job running again, and the next one ends it a second time. Each end is told once.
      const late = async (route) => {
        const response = await route.fetch();
        await new Promise((r) => setTimeout(r, 1500));
        await route.fulfill({ response }).catch(() => {});
      };
      await tab.route(/\/v1\/jobs\?limit=/, late);
      await setHidden(tab, true);
      await tab.getByLabel("Name", { exact: true }).fill("in the background");
      const a = (await submitAccepted(tab)).job;
      await tab.getByLabel("Name", { exact: true }).fill("watched");
      const b = (await submitAccepted(tab)).job;
      for (const id of [a.id, b.id]) assert.equal((await finished(id)).status.state, "succeeded");
      await settles(title, "✓ 2 jobs ended — tessera", "the title after two jobs ended in the background");
      // Past a late answer or two: still two.
      await tab.waitForTimeout(3500);
      assert.equal(await title(), "✓ 2 jobs ended — tessera");
      const shown = await tab.evaluate(() => window.__shown);
      assert.deepEqual(shown.sort(), ["tessera: in the background done", "tessera: watched done"]);
      await tab.unroute(/\/v1\/jobs\?limit=/, late);
      await setHidden(tab, false);
      assert.equal(await title(), "tessera");

      // A job that ends while the tab is seen changes nothing.
      await tab.getByLabel("Time limit (s)").fill("");
      await tab.getByLabel("Samples per pixel").fill("1");
      const seen = (await submitAccepted(tab)).job;
      await finished(seen.id);
      await tab.waitForTimeout(1500);
      assert.equal(await title(), "tessera");
      assert.equal(await tab.evaluate(() => window.__shown.length), 2);
    } finally {
      await tab.close();
    }
  });
  assert.deepEqual(pageErrors, []);
});
