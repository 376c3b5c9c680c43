// Parameter controls generated from GET /v1/materials: each model lists its parameters with a JSON Schema, a default
// and the tightest numeric range. A reflectance (three numbers in [0, 1]) gets a colour picker, a bounded number a
// slider with a number field, an enum a select, a boolean a checkbox, anything else (nested materials, textures) a
// small JSON field.
//
// What the form shows is what renders. A parameter with a default shows it and is sent only once it was changed, so
// that the daemon applies the same default. A parameter without one (an override such as alpha_x, which otherwise
// follows roughness, or eta and k, which otherwise come from the named metal) is not set until its "Set" box is
// ticked: only then is its control shown, and sent.
//
// The order is one rule, PRIMARY_PARAMETERS: the parameters it names come first, in its order; every other one
// follows in the order of the model's schema (GET /v1/materials keeps it), folded under "Advanced".

// The parameters a user reaches for first, in the order they do: what colour, what metal (and, for Cook-Torrance,
// whether its Fresnel term is a metal's at all), how rough, how metallic, what index of refraction; then a model's own
// few (the specular lobe of Phong and Ward, glTF's transmission, the materials a mix or a two-sided material is made
// of). Anisotropy, the overrides of a named metal, emission, normal maps and the like are Advanced.
export const PRIMARY_PARAMETERS = [
  "base_color", "albedo", "diffuse", "kd", "rho_d", "radiance", "fresnel", "metal",
  "roughness", "alpha", "metallic", "ior",
  "ks", "rho_s", "exponent", "transmission",
  "material", "a", "b", "weight",
];

// Models the material tab does not offer: the preview stage would show nothing of them. `interface` is a boundary
// that is not drawn (it only marks where an object's medium begins, in a scene job).
export const NOT_ON_PREVIEW_STAGE = ["interface"];

// Presets the material tab offers: a model and its parameters, shown on the form as if typed. The subsurface ones have
// an index-matched surface (ior 1), behind which every scattering samples the lights (README, "Subsurface scattering");
// mean free paths are for the preview stage's spheres of radius 1.
export const MATERIAL_PRESETS = [
  {
    name: "Skin",
    material: {
      type: "subsurface", ior: 1, subsurface_color: [0.78, 0.52, 0.42], subsurface_radius: 0.08,
      subsurface_radius_scale: [1, 0.4, 0.2],
    },
  },
  {
    name: "Wax",
    material: {
      type: "subsurface", ior: 1, subsurface_color: [0.9, 0.78, 0.55], subsurface_radius: 0.25,
      subsurface_radius_scale: [1, 0.85, 0.6],
    },
  },
  {
    name: "Jade",
    material: {
      type: "subsurface", ior: 1, subsurface_color: [0.45, 0.75, 0.5], subsurface_radius: 0.5,
      subsurface_radius_scale: [0.7, 1, 0.8], subsurface_scatter_anisotropy: 0.3,
    },
  },
  {
    name: "Marble",
    material: {
      type: "subsurface", ior: 1, subsurface_color: [0.92, 0.91, 0.88], subsurface_radius: 0.12,
      subsurface_radius_scale: [1, 0.95, 0.9],
    },
  },
];

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

// sRGB transfer function (IEC 61966-2-1): colour pickers show display colours, parameters are linear.
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
// A colour parameter may be one number (grey) or three.
const asRgb = (v) => (typeof v === "number" ? [v, v, v] : isRgb(v) ? v : null);

// The schema branch a control edits: a scalar or colour map is "a number (or colour), or a texture"; the form edits
// the first branch and leaves textures to the JSON tab.
function plainBranch(s) {
  let b = s || {};
  while (Array.isArray(b.anyOf) && b.anyOf.length) b = b.anyOf[0];
  return b;
}

// What kind of control a parameter gets.
function controlKind(p) {
  const s = p.schema || {};
  const b = plainBranch(s);
  const def = p.default;
  if (Array.isArray(s.enum) || Array.isArray(b.enum)) return "enum";
  if (s.type === "boolean" || typeof def === "boolean") return "boolean";
  if (isRgb(def) || (def === undefined && /color|colour|albedo|radiance|emission/.test(p.name))) {
    return (p.maximum ?? Infinity) <= 1 ? "color" : "vector";
  }
  if (typeof def === "number" || b.type === "number" || b.type === "integer") return "number";
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

// The value an optional number starts at when it is set: its lower bound (one above an exclusive one), else 0.
function startValue(p, attrs) {
  const b = plainBranch(p.schema);
  const exclusive = p.schema?.exclusiveMinimum ?? b.exclusiveMinimum;
  if (Number.isFinite(exclusive)) return exclusive + 1;
  return attrs.min ?? 0;
}

// One parameter's control: { name, row, get(), set(v) }. get() is the value to send or undefined (not set, or still
// the default); set(v) shows a value (a duplicated job's) and returns false when the control cannot show it.
function parameterControl(p) {
  const kind = controlKind(p);
  const id = nextId(p.name);
  const words = p.name.replaceAll("_", " ");
  const label = el("label", { for: id, text: words[0].toUpperCase() + words.slice(1) });
  const hint = p.description ? el("small", { class: "hint", id: `${id}-hint`, text: p.description }) : null;
  const described = hint ? `${id}-hint` : undefined;
  const hasDefault = p.default !== undefined && p.default !== null;

  // read(): the control's value; show(v): puts v in it (false if it cannot); raw(): its text, to tell a change.
  let body;
  let read;
  let show;
  let raw;
  if (kind === "enum") {
    const values = p.schema.enum || plainBranch(p.schema).enum;
    const control = el("select", { id, "aria-describedby": described });
    for (const v of values) control.append(el("option", { value: v, text: v }));
    body = control;
    read = () => control.value;
    show = (v) => values.includes(v) && ((control.value = v), true);
    raw = () => control.value;
  } else if (kind === "boolean") {
    const control = el("input", { id, type: "checkbox", "aria-describedby": described });
    body = control;
    read = () => control.checked;
    show = (v) => typeof v === "boolean" && ((control.checked = v), true);
    raw = () => String(control.checked);
  } else if (kind === "color") {
    const control = el("input", { id, type: "color", "aria-describedby": described });
    const readout = el("output", { for: id, class: "mono" });
    const update = () => (readout.textContent = hexToLinear(control.value).map((v) => v.toFixed(3)).join(" "));
    control.addEventListener("input", update);
    body = el("span", { class: "color-row" }, control, readout);
    read = () => hexToLinear(control.value);
    show = (v) => {
      const rgb = asRgb(v);
      if (!rgb) return false;
      control.value = linearToHex(rgb);
      readout.textContent = rgb.map((x) => x.toFixed(3)).join(" ");
      return true;
    };
    raw = () => control.value;
  } else if (kind === "vector") {
    const inputs = [0, 1, 2].map((i) =>
      el("input", {
        type: "number",
        ...numberAttrs(p, false),
        "aria-label": `${p.name} ${"RGB"[i]}`,
        id: i === 0 ? id : undefined,
        "aria-describedby": described,
      }),
    );
    body = el("span", { class: "vector-row" }, ...inputs);
    read = () =>
      inputs.map((x) => {
        if (x.value.trim() === "" || !Number.isFinite(Number(x.value))) throw new Error(`${p.name}: enter numbers`);
        return Number(x.value);
      });
    show = (v) => {
      const rgb = asRgb(v);
      if (!rgb) return false;
      rgb.forEach((x, i) => (inputs[i].value = x));
      return true;
    };
    raw = () => inputs.map((x) => x.value).join(" ");
  } else if (kind === "number") {
    const integer = plainBranch(p.schema).type === "integer";
    const attrs = numberAttrs(p, integer);
    const number = el("input", { id, type: "number", ...attrs, "aria-describedby": described });
    let slider = null;
    if (attrs.min !== undefined && attrs.max !== undefined && attrs.max - attrs.min <= 10000) {
      slider = el("input", {
        type: "range",
        min: attrs.min,
        max: attrs.max,
        step: integer ? 1 : (attrs.max - attrs.min) / 200,
        "aria-label": `${p.name} slider`,
        tabindex: "-1",
      });
      slider.addEventListener("input", () => (number.value = Number(slider.value).toPrecision(4) * 1));
      number.addEventListener("input", () => (slider.value = number.value));
      body = el("span", { class: "slider-row" }, slider, number);
    } else {
      body = number;
    }
    read = () => {
      const t = number.value.trim();
      if (t === "" || !Number.isFinite(Number(t))) throw new Error(`${p.name}: enter a number`);
      return Number(t);
    };
    show = (v) => {
      if (typeof v !== "number") return false;
      number.value = v;
      if (slider) slider.value = v;
      return true;
    };
    raw = () => number.value;
    if (!hasDefault) show(startValue(p, attrs));
  } else if (kind === "string") {
    const control = el("input", { id, type: "text", "aria-describedby": described });
    body = control;
    read = () => control.value || undefined;
    show = (v) => typeof v === "string" && ((control.value = v), true);
    raw = () => control.value;
  } else {
    const control = el("textarea", { id, rows: 2, class: "mono", spellcheck: "false", "aria-describedby": described });
    body = control;
    read = () => {
      const t = control.value.trim();
      if (!t) return undefined;
      try {
        return JSON.parse(t);
      } catch {
        throw new Error(`${p.name}: not valid JSON`);
      }
    };
    show = (v) => ((control.value = JSON.stringify(v)), true);
    raw = () => control.value.trim();
  }

  // A JSON or text field with nothing in it is unset by itself; other controls always hold a value, so a parameter
  // without a default gets a "Set" box and its control appears only when it is ticked.
  const emptyMeansUnset = kind === "json" || kind === "string";
  let enabled = null;
  if (!hasDefault && !emptyMeansUnset) {
    enabled = el("input", { type: "checkbox", "aria-label": `Set ${p.name}`, class: "set-box" });
    body.hidden = true;
    enabled.addEventListener("change", () => (body.hidden = !enabled.checked));
  } else if (hasDefault) {
    show(p.default);
  }
  const initial = raw();
  const head = enabled
    ? el("span", { class: "set-row" }, label, el("label", { class: "set-label" }, enabled, "Set"))
    : label;
  const row = el("div", { class: "field", "data-param": p.name }, head, body, hint);
  return {
    name: p.name,
    row,
    get() {
      if (enabled) return enabled.checked ? read() : undefined;
      if (hasDefault && raw() === initial) return undefined;
      return read();
    },
    set(v) {
      if (!show(v)) return false;
      if (enabled) {
        enabled.checked = true;
        body.hidden = false;
      }
      return true;
    },
  };
}

// Builds the form for one material model: its PRIMARY_PARAMETERS, then a closed "Advanced" group with the rest.
// Returns { element, value(), set(material) }: value() is the material object to send, set() shows a material's
// values (opening Advanced when one is there) and returns false if some cannot be shown (a texture in a number, an
// unknown key): the caller then offers the JSON tab instead.
export function materialForm(model) {
  const controls = new Map();
  for (const p of model.parameters || []) controls.set(p.name, parameterControl(p));
  const rank = (name) => PRIMARY_PARAMETERS.indexOf(name);
  const primary = [...controls.keys()].filter((n) => rank(n) >= 0).sort((a, b) => rank(a) - rank(b));
  const advanced = [...controls.keys()].filter((n) => rank(n) < 0);
  const element = el("div", { class: "material-params" }, ...primary.map((n) => controls.get(n).row));
  let details = null;
  if (advanced.length) {
    const summary = el("summary", { text: `Advanced (${advanced.length})` });
    details = el("details", { class: "more-params" }, summary, ...advanced.map((n) => controls.get(n).row));
    // A model with none of the primary parameters shows its own open.
    details.open = !primary.length;
    element.append(details);
  }
  return {
    element,
    value() {
      const m = { type: model.type };
      for (const [name, c] of controls) {
        const v = c.get();
        if (v !== undefined) m[name] = v;
      }
      return m;
    },
    set(material) {
      let all = true;
      for (const [name, v] of Object.entries(material)) {
        if (name === "type") continue;
        const c = controls.get(name);
        if (!c || !c.set(v)) all = false;
        else if (details && advanced.includes(name)) details.open = true;
      }
      return all;
    },
  };
}
