#!/usr/bin/env bash
# Renders one preview image per material model with tessera itself (the built-in material stage) into
# docs/materials/<model>.png, then regenerates the table in docs/materials.md from proto/schemas/material.schema.json.
#
#   clients/scripts/material-previews.sh            # uses build/clients/cli/tessera
#   TESSERA=build-mat/clients/cli/tessera SPP=256 clients/scripts/material-previews.sh
#   clients/scripts/material-previews.sh --docs-only   # only regenerate docs/materials.md
set -euo pipefail

docs_only=0
[[ "${1:-}" == "--docs-only" ]] && docs_only=1

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
tessera="${TESSERA:-$root/build/clients/cli/tessera}"
spp="${SPP:-128}"
size="${SIZE:-256}"
out="$root/docs/materials"
[[ $docs_only == 1 || -x "$tessera" ]] || { echo "material-previews: no tessera binary at $tessera (build it, or set TESSERA)" >&2; exit 2; }
mkdir -p "$out"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# One representative material per model: "<model> <material JSON>".
previews=(
  'lambert {"type": "lambert", "albedo": [0.75, 0.3, 0.2]}'
  'emission {"type": "emission", "radiance": [3.0, 2.2, 1.2]}'
  'phong {"type": "phong", "kd": [0.5, 0.1, 0.1], "ks": 0.4, "exponent": 60}'
  'blinn_phong {"type": "blinn_phong", "kd": [0.1, 0.3, 0.5], "ks": 0.4, "exponent": 120}'
  'phong_classic {"type": "phong_classic", "kd": [0.5, 0.1, 0.1], "ks": 0.4, "exponent": 60}'
  'blinn_phong_classic {"type": "blinn_phong_classic", "kd": [0.1, 0.3, 0.5], "ks": 0.4, "exponent": 120}'
  'cook_torrance {"type": "cook_torrance", "distribution": "beckmann", "masking": "v_cavity", "roughness": 0.25, "kd": [0.35, 0.3, 0.05], "ks": 0.6}'
  'ward {"type": "ward", "rho_d": [0.1, 0.12, 0.2], "rho_s": 0.7, "alpha_x": 0.05, "alpha_y": 0.4}'
  'dielectric {"type": "dielectric", "ior": 1.5, "roughness": 0.0}'
  'thin_dielectric {"type": "thin_dielectric", "ior": 1.5, "transmittance": [0.8, 0.95, 0.85]}'
  'conductor {"type": "conductor", "metal": "copper", "alpha_x": 0.05, "alpha_y": 0.35}'
  'plastic {"type": "plastic", "diffuse": [0.1, 0.35, 0.6], "roughness": 0.08}'
  'gltf_pbr {"type": "gltf_pbr", "base_color": [0.9, 0.6, 0.2], "metallic": 0.0, "roughness": 0.45, "clearcoat": 1.0, "clearcoat_roughness": 0.05}'
  'mix {"type": "mix", "a": {"type": "lambert", "albedo": [0.7, 0.7, 0.65]}, "b": {"type": "conductor", "metal": "gold", "roughness": 0.15}, "weight": {"checker": {"a": 0, "b": 1, "scale": 8}}}'
  'two_sided {"type": "two_sided", "material": {"type": "plastic", "diffuse": [0.6, 0.5, 0.1], "roughness": 0.2}}'
  'subsurface {"type": "subsurface", "subsurface_color": [0.9, 0.75, 0.5], "subsurface_radius": 0.3, "subsurface_radius_scale": [1, 0.8, 0.6], "ior": 1.45, "roughness": 0.1}'
)

for entry in "${previews[@]}"; do
  [[ $docs_only == 1 ]] && break
  model="${entry%% *}"
  material="${entry#* }"
  job="$work/$model.json"
  printf '{"kind": "material", "material": %s, "render": {"width": %d, "height": %d, "spp": %d, "seed": 1}}\n' \
    "$material" "$size" "$size" "$spp" > "$job"
  echo "material-previews: $model" >&2
  "$tessera" render "$job" -o "$out/$model.png" -q
done

# The table of models, their parameters and previews, from the schema.
python3 - "$root" <<'PY'
import json, sys, pathlib
root = pathlib.Path(sys.argv[1])
schema = json.loads((root / "proto/schemas/material.schema.json").read_text())
defs = schema["$defs"]
def fmt(v):
    return json.dumps(v, separators=(", ", ": ")).replace("|", "\\|")
def kind(p):
    ref = p.get("$ref", "")
    if ref.endswith("_map"):
        return {"reflectance_map": "colour in [0,1] / texture", "rgb_map": "colour / texture",
                "scalar_map": "number / texture"}[ref.split("/")[-1]]
    if ref == "#":
        return "material"
    if ref.endswith("/rgb"):
        return "RGB"
    if "enum" in p:
        return " \\| ".join(f"`{e}`" for e in p["enum"])
    return p.get("type", "")
lines = []
lines.append("# Materials\n")
lines.append("Every model tessera can render, by its `type` name (the contract is `proto/schemas/material.schema.json`; "
             "`GET /v1/materials` serves the same list). Each preview is a material job on the built-in stage, rendered "
             "by tessera itself with `clients/scripts/material-previews.sh`, which also regenerates this page.\n")
lines.append("Any parameter of kind *texture* also takes an image texture, `{\"texture\": \"wood.png\", \"wrap\": "
             "\"repeat\", \"scale\": [4, 4]}` (PNG/JPEG/EXR through OpenImageIO, bilinear, wrap `repeat` | `clamp` | "
             "`mirror`, file relative to the scene's folder), or a checkerboard, `{\"checker\": {\"a\": 0.8, \"b\": 0.2, "
             "\"scale\": 8}}`. Every model also takes `emission` (radiance) and `one_sided`.\n")
lines.append("The physics of each model, its sources and its tests are in the header comment of its file in "
             "`renderer/material/`; `tests/materials/` checks every model statistically (chi-square of sampling against "
             "the pdf, energy, reciprocity, Fresnel closed forms).\n")
lines.append("| model | preview | parameters (default, range) |")
lines.append("| --- | --- | --- |")
for t in schema["properties"]["type"]["enum"]:
    d = defs[t]
    params = []
    for k, p in d["properties"].items():
        if k in ("type", "emission", "one_sided"):
            continue
        s = f"`{k}` ({kind(p)}"
        if "default" in p:
            s += f", default `{fmt(p['default'])}`"
        if "minimum" in p or "maximum" in p:
            s += f", {p.get('minimum', '')}..{p.get('maximum', '')}"
        s += f"): {p.get('description', '')}"
        params.append(s)
    img = f"![{t}](materials/{t}.png)" if (root / f"docs/materials/{t}.png").exists() else ""
    lines.append(f"| **`{t}`** — {d['title']}: {d['description']} | {img} | " + "<br>".join(params) + " |")
(root / "docs/materials.md").write_text("\n".join(lines) + "\n")
print("material-previews: wrote docs/materials.md", file=sys.stderr)
PY
