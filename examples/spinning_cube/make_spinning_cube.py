#!/usr/bin/env python3
"""Writes SpinningCube.glb: a cube that slides across a floor and turns half a revolution in 2 seconds (48 frames
at 24 fps), a camera and a sun. Every byte comes from this script (no third-party content): CC0.

glTF 2.0: one buffer; the cube's translation and rotation channels are LINEAR (rotations slerped, 3.11 and Appendix
C), keyframes at 0, 1 and 2 s; KHR_lights_punctual for the sun. Run: python3 make_spinning_cube.py [OUT.glb]
"""
import json
import math
import struct
import sys

blob = bytearray()
views, accessors = [], []


def add(fmt, values, type_, count, target=None, minmax=False, component=5126):
    """Appends the packed values as a buffer view and an accessor; returns the accessor's index."""
    while len(blob) % 4:
        blob.append(0)
    data = struct.pack("<" + fmt * (len(values) // len(fmt)), *values)
    view = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
    if target:
        view["target"] = target
    blob.extend(data)
    views.append(view)
    acc = {"bufferView": len(views) - 1, "componentType": component, "count": count, "type": type_}
    if minmax:
        n = len(values) // count
        acc["min"] = [min(values[i::n]) for i in range(n)]
        acc["max"] = [max(values[i::n]) for i in range(n)]
    accessors.append(acc)
    return len(accessors) - 1


def box(hx, hy, hz):
    """24 vertices (4 a face, each face its own normal) and 36 indices, counter-clockwise seen from outside."""
    pos, nrm, idx = [], [], []
    for axis in range(3):
        for sign in (1, -1):
            n = [0, 0, 0]
            n[axis] = sign
            u, v = (axis + 1) % 3, (axis + 2) % 3
            base = len(pos) // 3
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0, 0, 0]
                p[axis] = sign
                p[u] = a
                p[v] = b * sign
                pos += [p[0] * hx, p[1] * hy, p[2] * hz]
                nrm += n
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return pos, nrm, idx


def mesh(pos, nrm, idx, material):
    p = add("f", pos, "VEC3", len(pos) // 3, 34962, minmax=True)
    n = add("f", nrm, "VEC3", len(nrm) // 3, 34962)
    i = add("H", idx + ([0] if len(idx) % 2 else []), "SCALAR", len(idx), 34963, component=5123)
    return {"primitives": [{"attributes": {"POSITION": p, "NORMAL": n}, "indices": i, "material": material}]}


def about_y(deg):
    h = math.radians(deg) / 2
    return [0.0, math.sin(h), 0.0, math.cos(h)]


cube = mesh(*box(0.5, 0.5, 0.5), 0)
floor = mesh(*box(4, 0.05, 3), 1)
times = add("f", [0.0, 1.0, 2.0], "SCALAR", 3, minmax=True)
slide = add("f", [-1.5, 0.5, 0.0, 0.0, 0.9, 0.0, 1.5, 0.5, 0.0], "VEC3", 3)
turn = add("f", about_y(0) + about_y(90) + about_y(180), "VEC4", 3)
pitch = math.radians(-14) / 2
gltf = {
    "asset": {"version": "2.0", "generator": "tessera examples/spinning_cube/make_spinning_cube.py"},
    "extensionsUsed": ["KHR_lights_punctual"],
    "extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional", "intensity": 3.0,
                                                        "color": [1.0, 0.95, 0.9]}]}},
    "scene": 0,
    "scenes": [{"nodes": [0, 1, 2, 3]}],
    "nodes": [
        {"name": "cube", "mesh": 0, "translation": [-1.5, 0.5, 0.0]},
        {"name": "floor", "mesh": 1, "translation": [0.0, -0.05, 0.0]},
        {"name": "camera", "camera": 0, "translation": [0.0, 1.6, 6.0],
         "rotation": [math.sin(pitch), 0.0, 0.0, math.cos(pitch)]},
        {"name": "sun", "rotation": [-0.4, 0.3, 0.1, 0.86],
         "extensions": {"KHR_lights_punctual": {"light": 0}}},
    ],
    "meshes": [cube, floor],
    "materials": [
        {"name": "orange", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.35, 0.08, 1], "metallicFactor": 0.0,
                                                    "roughnessFactor": 0.4}},
        {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1], "metallicFactor": 0.0,
                                                   "roughnessFactor": 0.8}},
    ],
    "cameras": [{"type": "perspective", "perspective": {"yfov": 0.6, "aspectRatio": 16 / 9, "znear": 0.1}}],
    "animations": [{"name": "slide", "samplers": [
        {"input": times, "output": slide, "interpolation": "LINEAR"},
        {"input": times, "output": turn, "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                     {"sampler": 1, "target": {"node": 0, "path": "rotation"}}]}],
    "accessors": accessors,
    "bufferViews": views,
    "buffers": [{"byteLength": len(blob)}],
}
# The sun's rotation as a unit quaternion.
q = gltf["nodes"][3]["rotation"]
norm = math.sqrt(sum(c * c for c in q))
gltf["nodes"][3]["rotation"] = [c / norm for c in q]

text = json.dumps(gltf, separators=(",", ":")).encode()
text += b" " * (-len(text) % 4)
while len(blob) % 4:
    blob.append(0)
glb = struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(text) + 8 + len(blob))
glb += struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + bytes(blob)
out = sys.argv[1] if len(sys.argv) > 1 else "SpinningCube.glb"
with open(out, "wb") as f:
    f.write(glb)
