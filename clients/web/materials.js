// Parameter controls generated from GET /v1/materials: each model lists its parameters with a JSON Schema, a default
// and the tightest numeric range. A reflectance (three numbers in [0, 1]) gets a colour picker, a bounded number a
// slider with a number field, an enum a select, a boolean a checkbox, anything else (nested materials, textures) a
// small JSON field.

let uid = 0;
const nextId = (name) => `mat-${name}-${++uid}`;

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else e.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children) if (c) e.append(c);
  return e;
}

// sRGB transfer function: colour pickers show display colours, parameters are linear.
const toLinear = (c) => (c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4);
const toSrgb = (l) => (l <= 0.0031308 ? 12.92 * l : 1.055 * l ** (1 / 2.4) - 0.055);
function linearToHex(rgb) {
  return (
    "#" +
    rgb
      .map((v) => Math.round(Math.min(1, Math.max(0, toSrgb(v))) * 255).toString(16).padStart(2, "0"))
      .join("")
  );
}
function hexToLinear(hex) {
  const n = parseInt(hex.slice(1), 16);
  return [(n >> 16) & 255, (n >> 8) & 255, n & 255].map((c) => Number(toLinear(c / 255).toFixed(4)));
}

const isRgb = (v) => Array.isArray(v) && v.length === 3 && v.every((x) => typeof x === "number");

// What kind of control a parameter gets.
function controlKind(p) {
  const s = p.schema || {};
  const def = p.default;
  if (Array.isArray(s.enum) || Array.isArray(s.anyOf?.[0]?.enum)) return "enum";
  if (s.type === "boolean" || typeof def === "boolean") return "boolean";
  if (isRgb(def) || (def === undefined && /color|colour|albedo|radiance|emission/.test(p.name))) {
    return (p.maximum ?? Infinity) <= 1 ? "color" : "vector";
  }
  if (typeof def === "number" || s.type === "number" || s.type === "integer") return "number";
  if (typeof def === "string" || s.type === "string") return "string";
  return "json";
}

function numberAttrs(p, integer) {
  const lo = Number.isFinite(p.minimum) ? p.minimum : undefined;
  const hi = Number.isFinite(p.maximum) ? p.maximum : undefined;
  let step = integer ? 1 : "any";
  if (!integer && lo !== undefined && hi !== undefined && hi - lo <= 10) step = 0.01;
  return { min: lo, max: hi, step };
}

// Builds the form rows for one material model; returns { element, value() } where value() is the material object.
export function materialForm(model) {
  const rows = [];
  const getters = [];
  for (const p of model.parameters || []) {
    const kind = controlKind(p);
    const id = nextId(p.name);
    const words = p.name.replaceAll("_", " ");
    const label = el("label", { for: id, text: words[0].toUpperCase() + words.slice(1) });
    const hint = p.description ? el("small", { class: "hint", id: `${id}-hint`, text: p.description }) : null;
    const described = hint ? `${id}-hint` : undefined;
    let control;
    let get;
    if (kind === "enum") {
      const values = p.schema.enum || p.schema.anyOf[0].enum;
      control = el("select", { id, "aria-describedby": described });
      for (const v of values) control.append(el("option", { value: v, text: v }));
      if (p.default !== undefined) control.value = p.default;
      get = () => control.value;
    } else if (kind === "boolean") {
      control = el("input", { id, type: "checkbox", "aria-describedby": described });
      control.checked = Boolean(p.default);
      get = () => control.checked;
    } else if (kind === "color") {
      const def = isRgb(p.default) ? p.default : [0, 0, 0];
      control = el("input", { id, type: "color", value: linearToHex(def), "aria-describedby": described });
      const readout = el("output", { for: id, class: "mono", text: def.map((v) => v.toFixed(3)).join(" ") });
      control.addEventListener("input", () => {
        readout.textContent = hexToLinear(control.value).map((v) => v.toFixed(3)).join(" ");
      });
      const wrap = el("span", { class: "color-row" }, control, readout);
      get = () => hexToLinear(control.value);
      rows.push(el("div", { class: "field" }, label, wrap, hint));
      getters.push([p.name, get, p.default]);
      continue;
    } else if (kind === "vector") {
      const def = isRgb(p.default) ? p.default : [0, 0, 0];
      const inputs = def.map((v, i) =>
        el("input", {
          type: "number",
          value: v,
          ...numberAttrs(p, false),
          "aria-label": `${p.name} ${"RGB"[i]}`,
          id: i === 0 ? id : undefined,
          "aria-describedby": described,
        }),
      );
      const wrap = el("span", { class: "vector-row" }, ...inputs);
      get = () => inputs.map((x) => Number(x.value));
      rows.push(el("div", { class: "field" }, label, wrap, hint));
      getters.push([p.name, get, p.default]);
      continue;
    } else if (kind === "number") {
      const integer = p.schema?.type === "integer";
      const attrs = numberAttrs(p, integer);
      const def = typeof p.default === "number" ? p.default : (attrs.min ?? 0);
      const number = el("input", { id, type: "number", value: def, ...attrs, "aria-describedby": described });
      if (attrs.min !== undefined && attrs.max !== undefined && attrs.max - attrs.min <= 10000) {
        const slider = el("input", {
          type: "range",
          value: def,
          min: attrs.min,
          max: attrs.max,
          step: integer ? 1 : (attrs.max - attrs.min) / 200,
          "aria-label": `${p.name} slider`,
          tabindex: "-1",
        });
        slider.addEventListener("input", () => (number.value = Number(slider.value).toPrecision(4) * 1));
        number.addEventListener("input", () => (slider.value = number.value));
        rows.push(el("div", { class: "field" }, label, el("span", { class: "slider-row" }, slider, number), hint));
      } else {
        rows.push(el("div", { class: "field" }, label, number, hint));
      }
      getters.push([p.name, () => Number(number.value), p.default]);
      continue;
    } else if (kind === "string") {
      control = el("input", { id, type: "text", value: p.default ?? "", "aria-describedby": described });
      get = () => control.value || undefined;
    } else {
      control = el("textarea", { id, rows: 2, class: "mono", spellcheck: "false", "aria-describedby": described });
      control.value = p.default === undefined ? "" : JSON.stringify(p.default);
      get = () => {
        const t = control.value.trim();
        if (!t) return undefined;
        try {
          return JSON.parse(t);
        } catch {
          throw new Error(`${p.name}: not valid JSON`);
        }
      };
    }
    rows.push(el("div", { class: "field" }, label, control, hint));
    getters.push([p.name, get, p.default]);
  }
  const element = el("div", { class: "material-params" }, ...rows);
  if (!rows.length) element.append(el("p", { class: "muted", text: "This model has no parameters." }));
  return {
    element,
    value() {
      const m = { type: model.type };
      for (const [name, get, def] of getters) {
        const v = get();
        if (v === undefined) continue;
        // Optional parameters with no default (e.g. an alias) stay out unless they were set to something.
        if (def === undefined && (v === false || (Array.isArray(v) && v.every((x) => x === 0)))) continue;
        m[name] = v;
      }
      return m;
    },
  };
}
