// A frame range job's frames in the job view, read from its status's "frames" (counts, the frames done, rendering
// and failed as ranges of frame numbers, last_done, and the URI templates of a frame's results): a strip of
// thumbnails that shows a window of at most STRIP_SIZE frames of the range, never the whole range at once, following
// the latest finished frame until the user picks a frame or pages; a player that steps through the finished frames at
// the job's render.fps; and a scrubber over the whole range. The page decides how a frame is shown (FrameStrip's
// `show` callback); this module fetches and keeps the frames' PNGs, a bounded number of them.
import { getBlob } from "./api.js";

export const STRIP_SIZE = 12;
// Frames kept decoded for the player and the thumbnails: about 1 MB each at 640×360.
const CACHE_SIZE = 96;
// Frames the player fetches ahead of the one it shows.
const PREFETCH = 6;

// The i-th frame of a range, and a frame's place in it (frames start + k step up to end).
export const frameAt = (f, i) => f.start + i * f.step;
export const indexOf = (f, frame) => Math.round((frame - f.start) / f.step);
// Whether a frame is in a status's list of ranges, [[first, last], ...]: every step-th frame between them.
export const inRanges = (ranges, frame) => (ranges || []).some(([a, b]) => frame >= a && frame <= b);

// "done", "running", "failed" or "queued". A status lists at most 64 ranges a kind (ranges_truncated): a frame past
// the last done range listed, not rendering nor failed, and not after last_done, is taken for done.
export function frameState(f, frame) {
  if (inRanges(f.done_ranges, frame)) return "done";
  if (inRanges(f.running_ranges, frame)) return "running";
  if (inRanges(f.failed_ranges, frame)) return "failed";
  if (f.ranges_truncated && f.last_done != null && frame <= f.last_done) {
    const listed = f.done_ranges?.length ? f.done_ranges[f.done_ranges.length - 1][1] : -Infinity;
    if (frame > listed) return "done";
  }
  return "queued";
}

export function frameUrl(f, frame, ext) {
  const template = f.links?.[`result_${ext}`];
  return template ? template.replaceAll("{frame}", String(frame)) : null;
}

// The frames' PNGs as ImageBitmaps, each fetched once while kept; the oldest dropped past CACHE_SIZE.
class FrameImages {
  constructor() {
    this.jobId = null;
    this.map = new Map(); // frame -> Promise<ImageBitmap>
  }
  reset(jobId) {
    if (jobId === this.jobId) return;
    this.clear();
    this.jobId = jobId;
  }
  clear() {
    for (const p of this.map.values()) p.then((b) => b.close?.(), () => {});
    this.map.clear();
  }
  get(f, frame) {
    let p = this.map.get(frame);
    if (p) {
      this.map.delete(frame);
      this.map.set(frame, p); // most recently used last
      return p;
    }
    p = getBlob(frameUrl(f, frame, "png")).then((blob) => createImageBitmap(blob));
    p.catch(() => this.map.get(frame) === p && this.map.delete(frame));
    this.map.set(frame, p);
    while (this.map.size > CACHE_SIZE) {
      const [old, op] = this.map.entries().next().value;
      this.map.delete(old);
      op.then((b) => b.close?.(), () => {});
    }
    return p;
  }
  // The bitmap if it has arrived, else null (and it is fetched).
  ready(f, frame) {
    const p = this.get(f, frame);
    if (!p.settled) p.then((b) => ((p.settled = true), (p.value = b)), () => (p.settled = true));
    return p.value ?? null;
  }
}

// The strip, player and scrubber of one job at a time. `els`: panel, strip, counts, play, fps, scrubber, label,
// earlier, later (buttons paging the strip). `show(frame, how)`: the page shows a frame; how is "pick" (a click on
// the strip, or the range's end: shown as a finished image) or "play" (the player or the scrubber: its PNG, `bitmap`).
export class FrameStrip {
  constructor(els, show) {
    this.els = els;
    this.show = show;
    this.images = new FrameImages();
    this.job = null;
    this.f = null;
    this.current = null; // the frame shown
    this.picked = null; // the frame last shown as a finished image
    this.follow = true; // the window and the viewer follow the latest finished frame
    this.first = 0; // the index of the window's first frame
    this.playing = false;
    this.timer = null;
    this.thumbs = new Map(); // frame -> object URL of its PNG, for the thumbnails in the window
    els.play.addEventListener("click", () => (this.playing ? this.pause() : this.play()));
    els.earlier.addEventListener("click", () => this.page(-1));
    els.later.addEventListener("click", () => this.page(1));
    els.scrubber.addEventListener("input", () => this.scrub(Number(els.scrubber.value)));
    els.strip.addEventListener("click", (e) => {
      const b = e.target.closest(".frame-thumb");
      if (b && b.dataset.state === "done") this.pick(Number(b.dataset.frame));
    });
  }

  // A job's status: hides the panel for a job of one image; a new job starts following its latest frame.
  update(job) {
    const f = job?.frames || null;
    if (!job || job.id !== this.job?.id) this.reset(job?.id ?? null);
    this.job = job;
    this.f = f;
    this.els.panel.hidden = !f;
    if (!f) return;
    const fps = this.fps();
    this.els.fps.textContent = `${fps} fps`;
    const parts = [`${f.done} of ${f.total} frames done`];
    if (f.running) parts.push(`${f.running} rendering`);
    if (f.failed) parts.push(`${f.failed} failed`);
    this.els.counts.textContent = parts.join(" · ");
    this.els.scrubber.max = String(f.total - 1);
    this.els.play.disabled = f.done === 0;
    if (this.follow && !this.playing && f.last_done != null) {
      this.windowAround(indexOf(f, f.last_done), true);
      // Once the range has ended, its latest frame shows as a finished image (while it renders, the job's preview
      // is that frame already).
      this.setCurrent(f.last_done);
      if (["succeeded", "failed", "cancelled"].includes(job.state) && this.picked !== f.last_done) this.pick(f.last_done, true);
    }
    this.render();
  }

  reset(jobId) {
    this.pause();
    this.images.reset(jobId);
    for (const url of this.thumbs.values()) URL.revokeObjectURL(url);
    this.thumbs.clear();
    this.current = null;
    this.picked = null;
    this.follow = true;
    this.first = 0;
    this.els.strip.replaceChildren();
    delete this.els.strip.dataset.signature;
  }

  fps() {
    const fps = Number(this.job?.render?.fps);
    return fps > 0 ? fps : 24;
  }

  // The window holds index i: at its end when following (the latest frame last), else where it already is if it
  // holds i, else around it.
  windowAround(i, atEnd = false) {
    const total = this.f.total;
    const size = Math.min(STRIP_SIZE, total);
    if (atEnd) this.first = i - size + 1 + Math.min(2, total - 1 - i);
    else if (i < this.first || i >= this.first + size) this.first = i - Math.floor(size / 2);
    this.first = Math.max(0, Math.min(this.first, total - size));
  }

  page(direction) {
    if (!this.f) return;
    this.follow = false;
    const size = Math.min(STRIP_SIZE, this.f.total);
    this.first = Math.max(0, Math.min(this.first + direction * size, this.f.total - size));
    this.render();
  }

  setCurrent(frame) {
    this.current = frame;
    const f = this.f;
    this.els.scrubber.value = String(indexOf(f, frame));
    this.els.label.textContent = `frame ${frame} (${f.start}–${f.end}${f.step > 1 ? ` every ${f.step}` : ""})`;
    this.els.panel.dataset.frame = String(frame);
  }

  // A click on a finished frame: the player stops and the viewer shows it as a finished image. `following`: the range
  // ended, and its latest frame shows so.
  pick(frame, following = false) {
    this.pause();
    this.follow = following;
    this.picked = frame;
    this.setCurrent(frame);
    this.windowAround(indexOf(this.f, frame));
    this.render();
    this.show(frame, "pick");
  }

  // The scrubber at index i: its frame, when finished, shows at once (its PNG).
  async scrub(i) {
    this.pause();
    this.follow = false;
    const frame = frameAt(this.f, i);
    this.setCurrent(frame);
    this.windowAround(i);
    this.render();
    if (frameState(this.f, frame) !== "done") return;
    await this.showPng(frame);
  }

  async showPng(frame) {
    this.picked = null;
    const id = this.job.id;
    try {
      const bitmap = await this.images.get(this.f, frame);
      if (this.job?.id === id && this.current === frame) this.show(frame, "play", bitmap);
    } catch {
      // gone (the job was requeued or deleted): the next status says so
    }
  }

  // The finished frames after `frame`, in order, wrapping to the range's first.
  nextDone(frame, count = 1) {
    const f = this.f;
    const out = [];
    let i = frame == null ? -1 : indexOf(f, frame);
    for (let n = 0; n < f.total && out.length < count; ++n) {
      i = (i + 1) % f.total;
      const fr = frameAt(f, i);
      if (frameState(f, fr) === "done") out.push(fr);
    }
    return out;
  }

  play() {
    if (!this.f || this.f.done === 0) return;
    this.playing = true;
    this.follow = false;
    this.els.play.textContent = "Pause frames";
    this.els.play.setAttribute("aria-pressed", "true");
    this.els.panel.dataset.playing = "true";
    this.tick();
  }

  pause() {
    this.playing = false;
    clearTimeout(this.timer);
    this.timer = null;
    this.els.play.textContent = "Play frames";
    this.els.play.setAttribute("aria-pressed", "false");
    this.els.panel.dataset.playing = "false";
  }

  // One step of the player: the next finished frame once its PNG has arrived (the player waits for it rather than
  // skip it), then the one after at 1 / fps.
  tick() {
    if (!this.playing) return;
    const f = this.f;
    const [next, ...ahead] = this.nextDone(this.current, 1 + PREFETCH);
    for (const fr of ahead) this.images.get(f, fr);
    const bitmap = next == null ? null : this.images.ready(f, next);
    if (bitmap) {
      this.picked = null;
      this.setCurrent(next);
      this.windowAround(indexOf(f, next));
      this.render();
      this.show(next, "play", bitmap);
    }
    this.timer = setTimeout(() => this.tick(), bitmap ? 1000 / this.fps() : 20);
  }

  // The window's thumbnails: a finished frame shows its PNG, the others their state.
  render() {
    const f = this.f;
    if (!f) return;
    const size = Math.min(STRIP_SIZE, f.total);
    const states = [];
    for (let i = this.first; i < this.first + size; ++i) states.push(frameState(f, frameAt(f, i)));
    // Rebuilt only when what it shows changes: a status arrives many times a second.
    const signature = `${this.job.id} ${this.first} ${this.current} ${states.join(",")}`;
    if (this.els.strip.dataset.signature === signature) return;
    this.els.strip.dataset.signature = signature;
    const wanted = new Set();
    const cells = [];
    for (let i = this.first; i < this.first + size; ++i) {
      const frame = frameAt(f, i);
      const state = states[i - this.first];
      const b = document.createElement("button");
      b.type = "button";
      b.className = "frame-thumb";
      b.dataset.frame = String(frame);
      b.dataset.state = state;
      b.disabled = state !== "done";
      b.setAttribute("aria-pressed", String(frame === this.current));
      b.title = `frame ${frame}: ${state}`;
      if (state === "done") {
        wanted.add(frame);
        const img = document.createElement("img");
        img.alt = `frame ${frame}`;
        const url = this.thumbs.get(frame);
        if (url) img.src = url;
        else this.thumbnail(frame);
        b.append(img);
      }
      const label = document.createElement("span");
      label.textContent = String(frame);
      b.append(label);
      cells.push(b);
    }
    this.els.strip.replaceChildren(...cells);
    this.els.earlier.disabled = this.first === 0;
    this.els.later.disabled = this.first + size >= f.total;
    // Thumbnails out of the window are let go.
    for (const [frame, url] of this.thumbs) {
      if (!wanted.has(frame)) {
        URL.revokeObjectURL(url);
        this.thumbs.delete(frame);
      }
    }
  }

  // A finished frame's PNG for its thumbnail, fetched once while its frame is in the window; one that cannot be
  // fetched now is asked for again with the next status.
  async thumbnail(frame) {
    const id = this.job.id;
    if (this.thumbs.has(frame)) return;
    this.thumbs.set(frame, ""); // under way
    let url;
    try {
      url = URL.createObjectURL(await getBlob(frameUrl(this.f, frame, "png")));
    } catch {
      if (this.thumbs.get(frame) === "") this.thumbs.delete(frame);
      delete this.els.strip.dataset.signature;
      return;
    }
    if (this.job?.id !== id) return URL.revokeObjectURL(url);
    // Kept even when the window has moved on meanwhile: the next rebuild shows it or lets it go.
    const old = this.thumbs.get(frame);
    if (old) URL.revokeObjectURL(old);
    this.thumbs.set(frame, url);
    const img = this.els.strip.querySelector(`.frame-thumb[data-frame="${frame}"] img`);
    if (img) img.src = url;
  }
}
