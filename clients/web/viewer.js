// The job view's image viewer: a canvas showing an image fitted to its frame (never above 1:1) or zoomed (1:1 and
// above, pixels kept sharp) and panned by dragging; the pixel under the cursor read out; and an A/B wipe against a second image.
//
// An image is either "linear" (a decoded EXR: radiance, to which the viewer applies the exposure in stops and the
// tone curve itself, as the daemon does for its PNG) or "display" (an 8-bit sRGB PNG, shown as it is). The display
// transform is the daemon's (renderer/image_io.cpp, to_display): scale by 2^exposure, the tone curve ("clamp", or
// Narkowicz's 2015 fit of the ACES filmic curve), the sRGB encoding of IEC 61966-2-1, rounding to 8 bits. The
// browser test checks that the viewer at the job's own settings reproduces the daemon's PNG.
//
// A render pass is shown as the daemon's PNG of it (its look, made in one place: renderer/aov.cpp, aov_look) with
// the pass's own numbers from the EXR beside it: the readout gives those (a depth, an id, a normal), not the look's;
// for a Cryptomatte pass, the names of the pixel's objects or materials with their coverage.

import { cryptomatteAt } from "./exr.js";

const MIN_ZOOM = 1 / 64;
const MAX_ZOOM = 64;

function acesFit(x) {
  const v = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14);
  return Math.min(1, Math.max(0, v));
}
function srgbEncode(l) {
  if (!(l > 0)) return 0;
  if (l >= 1) return 1;
  return l <= 0.0031308 ? 12.92 * l : 1.055 * l ** (1 / 2.4) - 0.055;
}

// Linear RGB (Float32Array, 3 per pixel) to 8-bit RGBA with the daemon's display transform.
export function toDisplay(rgb, exposureEv, tonemap) {
  const scale = 2 ** exposureEv;
  const aces = tonemap === "aces";
  const out = new Uint8ClampedArray((rgb.length / 3) * 4);
  for (let i = 0, o = 0; i < rgb.length; i += 3, o += 4) {
    for (let c = 0; c < 3; ++c) {
      let v = rgb[i + c] * scale;
      if (!Number.isFinite(v)) v = v > 0 ? 1 : 0;
      if (aces) v = acesFit(v);
      out[o + c] = Math.round(srgbEncode(v) * 255);
    }
    out[o + 3] = 255;
  }
  return out;
}

// One image: its size, its linear values (or null), and a canvas holding what is drawn; for a render pass, pass:
// { name, channels, values } (a layer of exr.js's decodeExr; values null when the job wrote no EXR), or for a
// Cryptomatte pass { name, crypto } (exr.js's cryptomatteOfPass), read out as the names of the pixel's ids.
class Layer {
  constructor(image) {
    this.width = image.width;
    this.height = image.height;
    this.rgb = image.rgb || null;
    this.pass = image.pass || null;
    this.canvas = document.createElement("canvas");
    this.canvas.width = this.width;
    this.canvas.height = this.height;
    this.ctx = this.canvas.getContext("2d", { willReadFrequently: !this.rgb });
    if (!this.rgb) this.ctx.drawImage(image.bitmap, 0, 0);
    this.pixels = this.rgb ? null : this.ctx.getImageData(0, 0, this.width, this.height).data;
  }
  get linear() {
    return Boolean(this.rgb);
  }
  tone(exposureEv, tonemap) {
    if (!this.rgb) return;
    const data = toDisplay(this.rgb, exposureEv, tonemap);
    this.ctx.putImageData(new ImageData(data, this.width, this.height), 0, 0);
  }
  // The value at (x, y): [r, g, b] linear, or 8-bit sRGB; null outside.
  at(x, y) {
    if (x < 0 || y < 0 || x >= this.width || y >= this.height) return null;
    const i = y * this.width + x;
    return this.rgb ? [...this.rgb.subarray(3 * i, 3 * i + 3)] : [...this.pixels.subarray(4 * i, 4 * i + 3)];
  }
  // What the readout says of pixel (x, y), which is inside: a pass's channels by name, else R, G and B.
  describe(x, y) {
    if (this.pass?.crypto) {
      const ids = cryptomatteAt(this.pass.crypto, y * this.width + x);
      const v = ids.map((e) => `${e.name} ${(100 * e.coverage).toFixed(1)} %`);
      return `${this.pass.name} ${v.length ? v.join(", ") : "nothing"}`;
    }
    const values = this.pass?.values;
    if (values) {
      const n = this.pass.channels.length;
      const at = n * (y * this.width + x);
      const v = this.pass.channels.map((c, k) => `${c} ${fmtPassValue(values[at + k])}`);
      return `${this.pass.name} ${v.join(" ")}`;
    }
    const v = this.at(x, y);
    const kind = this.linear ? "" : this.pass ? ` (${this.pass.name}: its look, sRGB 8-bit)` : " (sRGB 8-bit)";
    return `R ${fmtValue(v[0], this.linear)} G ${fmtValue(v[1], this.linear)} B ${fmtValue(v[2], this.linear)}${kind}`;
  }
}

function fmtValue(v, linear) {
  if (!linear) return String(v);
  if (!Number.isFinite(v)) return String(v);
  return Math.abs(v) >= 1000 ? v.toExponential(2) : v.toPrecision(4);
}
// A pass's value: whole numbers (ids, sample counts) as they are.
const fmtPassValue = (v) => (Number.isInteger(v) ? String(v) : fmtValue(v, true));

export class ImageViewer {
  // root: the viewer's element, holding a <canvas>, [data-view] buttons (fit, actual, in, out, expand), an exposure
  // range and number, a tone select, a zoom label and a readout (found by their data-role).
  constructor(root) {
    this.root = root;
    this.canvas = root.querySelector("canvas");
    this.ctx = this.canvas.getContext("2d");
    this.role = (r) => root.querySelector(`[data-role="${r}"]`);
    this.a = null;
    this.b = null;
    this.split = 0.5; // where B starts, a fraction of the frame's width
    this.zoom = 1;
    this.panX = 0;
    this.panY = 0;
    this.fit = true;
    this.exposure = 0;
    this.tonemap = "clamp";
    this.drag = null;
    this.hover = null;
    this.bind();
    new ResizeObserver(() => this.draw()).observe(this.canvas);
  }

  bind() {
    for (const b of this.root.querySelectorAll("[data-view]")) {
      b.addEventListener("click", () => this.command(b.dataset.view));
    }
    const range = this.role("exposure");
    const number = this.role("exposure-value");
    range.addEventListener("input", () => this.setExposure(Number(range.value)));
    number.addEventListener("change", () => {
      const v = Number(number.value);
      if (Number.isFinite(v)) this.setExposure(Math.max(-20, Math.min(20, v)));
    });
    this.role("tonemap").addEventListener("change", (e) => this.setTonemap(e.target.value));
    const c = this.canvas;
    c.addEventListener("wheel", (e) => {
      if (!this.a) return;
      e.preventDefault();
      this.zoomAt(this.zoom * (e.deltaY < 0 ? 1.25 : 0.8), e.offsetX, e.offsetY);
    }, { passive: false });
    c.addEventListener("pointerdown", (e) => {
      if (!this.a || e.button !== 0) return;
      c.setPointerCapture(e.pointerId);
      const onSplit = this.b && Math.abs(e.offsetX - this.split * c.clientWidth) <= 6;
      this.drag = { x: e.offsetX, y: e.offsetY, panX: this.panX, panY: this.panY, split: onSplit };
    });
    c.addEventListener("pointermove", (e) => {
      if (this.drag?.split) {
        this.split = Math.max(0, Math.min(1, e.offsetX / c.clientWidth));
        this.draw();
      } else if (this.drag) {
        this.fit = false;
        this.panX = this.drag.panX + e.offsetX - this.drag.x;
        this.panY = this.drag.panY + e.offsetY - this.drag.y;
        this.draw();
      }
      this.hover = [e.offsetX, e.offsetY];
      this.readout();
    });
    const end = () => (this.drag = null);
    c.addEventListener("pointerup", end);
    c.addEventListener("pointercancel", end);
    c.addEventListener("pointerleave", () => {
      this.hover = null;
      this.readout();
    });
    c.addEventListener("dblclick", () => this.command(this.fit ? "actual" : "fit"));
    c.addEventListener("keydown", (e) => {
      const keys = { "+": "in", "=": "in", "-": "out", 0: "fit", 1: "actual" };
      const pan = { ArrowLeft: [40, 0], ArrowRight: [-40, 0], ArrowUp: [0, 40], ArrowDown: [0, -40] }[e.key];
      if (keys[e.key]) this.command(keys[e.key]);
      else if (pan && this.a) {
        this.fit = false;
        this.panX += pan[0];
        this.panY += pan[1];
        this.draw();
      } else if (e.key === "Escape" && this.root.classList.contains("expanded")) this.command("expand");
      else return;
      e.preventDefault();
    });
  }

  command(what) {
    const c = this.canvas;
    if (what === "fit") {
      this.fit = true;
      this.draw();
    } else if (what === "actual") {
      this.zoomAt(1, c.clientWidth / 2, c.clientHeight / 2);
    } else if (what === "in" || what === "out") {
      this.zoomAt(what === "in" ? this.zoom * 2 : this.zoom / 2, c.clientWidth / 2, c.clientHeight / 2);
    } else if (what === "expand") {
      const on = this.root.classList.toggle("expanded");
      this.root.querySelector('[data-view="expand"]')?.setAttribute("aria-pressed", String(on));
      if (on) c.focus();
    }
  }

  // Zooms to `z` keeping the image point under (x, y) of the canvas where it is.
  zoomAt(z, x, y) {
    if (!this.a) return;
    z = Math.max(MIN_ZOOM, Math.min(MAX_ZOOM, z));
    // Near 1:1, snap to it: a wheel's 1.25 steps would otherwise never land on it.
    if (Math.abs(z - 1) < 0.04) z = 1;
    const ix = (x - this.panX) / this.zoom;
    const iy = (y - this.panY) / this.zoom;
    this.fit = false;
    this.zoom = z;
    this.panX = x - ix * z;
    this.panY = y - iy * z;
    this.draw();
  }

  // Images: { width, height, rgb } (linear) or { width, height, bitmap } (display). `keepView` keeps the zoom and
  // pan (a newer preview of the same render).
  show(image, { keepView = false } = {}) {
    const first = !this.a || this.a.width !== image.width || this.a.height !== image.height;
    this.a = new Layer(image);
    this.a.tone(this.exposure, this.tonemap);
    if (first && !keepView) this.fit = true;
    this.root.dataset.source = this.a.linear ? "linear" : "display";
    this.controls();
    this.draw();
    this.readout();
  }
  compare(image) {
    this.b = image ? new Layer(image) : null;
    this.b?.tone(this.exposure, this.tonemap);
    this.split = 0.5;
    this.root.dataset.compare = this.b ? "on" : "off";
    this.controls();
    this.draw();
    this.readout();
  }
  clear() {
    this.a = null;
    this.b = null;
    this.root.dataset.source = "";
    this.root.dataset.compare = "off";
    this.controls();
    this.draw();
    this.readout();
  }
  // The job's own display settings: what the daemon's PNG shows.
  settings(exposureEv, tonemap) {
    this.exposure = exposureEv;
    this.tonemap = tonemap;
    this.role("tonemap").value = tonemap;
    this.syncExposure();
    this.a?.tone(this.exposure, this.tonemap);
    this.b?.tone(this.exposure, this.tonemap);
    this.draw();
  }
  setExposure(ev) {
    this.exposure = ev;
    this.syncExposure();
    this.a?.tone(ev, this.tonemap);
    this.b?.tone(ev, this.tonemap);
    this.draw();
  }
  setTonemap(t) {
    this.tonemap = t;
    this.a?.tone(this.exposure, t);
    this.b?.tone(this.exposure, t);
    this.draw();
  }
  syncExposure() {
    this.role("exposure").value = this.exposure;
    this.role("exposure-value").value = Number(this.exposure.toFixed(2));
  }
  // Exposure and tone apply to linear images only; the PNG is already tone-mapped.
  controls() {
    const linear = Boolean(this.a?.linear) && (!this.b || this.b.linear);
    for (const r of ["exposure", "exposure-value", "tonemap"]) this.role(r).disabled = !linear;
    for (const b of this.root.querySelectorAll("[data-view]")) {
      if (b.dataset.view !== "expand") b.disabled = !this.a;
    }
  }

  draw() {
    const c = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(c.clientWidth * dpr));
    const h = Math.max(1, Math.round(c.clientHeight * dpr));
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    const ctx = this.ctx;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, w, h);
    const label = this.role("zoom");
    if (!this.a) {
      label.textContent = "";
      return;
    }
    if (this.fit) {
      const cw = c.clientWidth;
      const ch = c.clientHeight;
      // Fit shrinks an image larger than the frame and leaves a smaller one at 1:1, centred: it shows the render's
      // pixels as they are. Enlarging them (sharp, each a block of screen pixels) is the user's zoom, not Fit's.
      this.zoom = Math.min(cw / this.a.width, ch / this.a.height, 1);
      this.panX = (cw - this.a.width * this.zoom) / 2;
      this.panY = (ch - this.a.height * this.zoom) / 2;
    }
    // Whole device pixels: at 1:1 and above, each image pixel then covers whole screen pixels.
    this.panX = Math.round(this.panX * dpr) / dpr;
    this.panY = Math.round(this.panY * dpr) / dpr;
    label.textContent = `${Math.round(this.zoom * 100)}%${this.fit ? " (fit)" : ""}`;
    this.root.dataset.zoom = String(this.zoom);
    this.root.dataset.pan = `${this.panX} ${this.panY}`;
    ctx.imageSmoothingEnabled = this.zoom < 1;
    ctx.setTransform(dpr * this.zoom, 0, 0, dpr * this.zoom, dpr * this.panX, dpr * this.panY);
    ctx.drawImage(this.a.canvas, 0, 0);
    if (this.b) {
      const x = this.split * c.clientWidth;
      ctx.save();
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.beginPath();
      ctx.rect(x * dpr, 0, w - x * dpr, h);
      ctx.clip();
      ctx.setTransform(dpr * this.zoom, 0, 0, dpr * this.zoom, dpr * this.panX, dpr * this.panY);
      ctx.clearRect(0, 0, this.b.width, this.b.height);
      ctx.drawImage(this.b.canvas, 0, 0);
      ctx.restore();
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.fillStyle = "#ffffffcc";
      ctx.fillRect(Math.round(x * dpr) - dpr, 0, 2 * dpr, h);
    }
  }

  // The image pixel under a point of the canvas (CSS pixels).
  pixelAt(x, y) {
    return [Math.floor((x - this.panX) / this.zoom), Math.floor((y - this.panY) / this.zoom)];
  }

  readout() {
    const out = this.role("readout");
    if (!this.a || !this.hover) {
      const pass = this.a?.pass;
      const what = pass ? `Pass ${pass.name}: the daemon's look${pass.values ? ", the EXR's values" : ""}` : null;
      out.textContent = this.a ? what || (this.a.linear ? "Linear EXR" : "PNG (sRGB, 8 bits)") : "";
      return;
    }
    const [x, y] = this.pixelAt(...this.hover);
    const parts = [];
    for (const [name, layer] of this.b ? [["A", this.a], ["B", this.b]] : [["", this.a]]) {
      if (!layer.at(x, y)) continue;
      parts.push(`${name ? `${name} ` : ""}${layer.describe(x, y)}`);
    }
    out.textContent = parts.length ? `x ${x}, y ${y}: ${parts.join(" · ")}` : `x ${x}, y ${y}: outside the image`;
    out.dataset.x = String(x);
    out.dataset.y = String(y);
  }
}
