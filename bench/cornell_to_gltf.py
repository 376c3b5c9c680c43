#!/usr/bin/env python3
"""Writes the Cornell box of proto/examples/cornell.json as a glTF 2.0 file (embedded buffer), with its camera and
the light as an emissive material (KHR_materials_emissive_strength), so that two renderers read the same scene.
Lambert albedo becomes a metallic-roughness material with metallic 0 and roughness 1.
Usage: cornell_to_gltf.py CORNELL_JOB.json OUT.gltf"""
import base64, json, math, struct, sys

job = json.load(open(sys.argv[1]))
scene = job["scene"]
names = list(scene["materials"].keys())
materials = []
for name in names:
    m = scene["materials"][name]
    if m["type"] == "emission":
        rad = m["radiance"]
        strength = max(rad)
        materials.append({"name": name, "emissiveFactor": [c / strength for c in rad],
                          "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": strength}},
                          "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0}})
    else:
        a = m["albedo"]
        a = a if isinstance(a, list) else [a, a, a]
        materials.append({"name": name, "pbrMetallicRoughness": {"baseColorFactor": a + [1], "metallicFactor": 0,
                                                                   "roughnessFactor": 1}})
buf = bytearray()
views, accessors, meshes, nodes = [], [], [], []
def add(data, fmt, count, type_, comp, target, minmax=None):
    while len(buf) % 4: buf.append(0)
    off = len(buf)
    buf.extend(struct.pack("<" + fmt * len(data), *data))
    views.append({"buffer": 0, "byteOffset": off, "byteLength": len(buf) - off, "target": target})
    acc = {"bufferView": len(views) - 1, "componentType": comp, "count": count, "type": type_}
    if minmax: acc["min"], acc["max"] = minmax
    accessors.append(acc)
    return len(accessors) - 1
for obj in scene["objects"]:
    if obj["shape"] == "rectangle":
        c, e1, e2 = obj["corner"], obj["edge1"], obj["edge2"]
        p = [c, [c[i] + e1[i] for i in range(3)], [c[i] + e1[i] + e2[i] for i in range(3)], [c[i] + e2[i] for i in range(3)]]
        pos = [v for q in p for v in q]
        idx = [0, 1, 2, 0, 2, 3]
    else:
        pos, idx = obj["positions"], obj["indices"]
    n = len(pos) // 3
    mins = [min(pos[i::3]) for i in range(3)]
    maxs = [max(pos[i::3]) for i in range(3)]
    pa = add(pos, "f", n, "VEC3", 5126, 34962, (mins, maxs))
    ia = add(idx, "I", len(idx), "SCALAR", 5125, 34963)
    meshes.append({"primitives": [{"attributes": {"POSITION": pa}, "indices": ia, "material": names.index(obj["material"])}]})
    nodes.append({"mesh": len(meshes) - 1})
# The camera: glTF cameras look down -Z with +Y up; build the rotation from the look-at frame.
cam = scene["camera"]
f = [cam["to"][i] - cam["from"][i] for i in range(3)]
l = math.sqrt(sum(x * x for x in f)); f = [x / l for x in f]
up = cam.get("up", [0, 1, 0])
r = [f[1] * up[2] - f[2] * up[1], f[2] * up[0] - f[0] * up[2], f[0] * up[1] - f[1] * up[0]]
l = math.sqrt(sum(x * x for x in r)); r = [x / l for x in r]
u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]]
z = [-x for x in f]
m = [[r[0], u[0], z[0]], [r[1], u[1], z[1]], [r[2], u[2], z[2]]]  # columns x=r, y=u, z=-f
tr = m[0][0] + m[1][1] + m[2][2]
if tr > 0:
    s = math.sqrt(tr + 1) * 2
    q = [(m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, s / 4]
else:
    i = max(range(3), key=lambda k: m[k][k]); j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1 + m[i][i] - m[j][j] - m[k][k]) * 2
    q = [0, 0, 0, (m[k][j] - m[j][k]) / s]
    q[i] = s / 4; q[j] = (m[j][i] + m[i][j]) / s; q[k] = (m[k][i] + m[i][k]) / s
w, h = job["render"]["width"], job["render"]["height"]
nodes.append({"camera": 0, "translation": cam["from"], "rotation": q})
gltf = {"asset": {"version": "2.0", "generator": "tessera bench/cornell_to_gltf.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes, "meshes": meshes,
        "materials": materials, "accessors": accessors, "bufferViews": views,
        "cameras": [{"type": "perspective", "perspective": {"yfov": math.radians(cam["fov_deg"]), "aspectRatio": w / h,
                                                            "znear": 0.01}}],
        "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()}]}
json.dump(gltf, open(sys.argv[2], "w"))
