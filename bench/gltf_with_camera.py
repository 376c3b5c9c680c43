#!/usr/bin/env python3
"""Writes a copy of a binary glTF (.glb) with a perspective camera framing the whole asset, for assets that have none,
so that two renderers see it from the same place: the camera looks at the centre of the asset's bounding sphere (the
POSITION accessors' min/max corners through each node's world transform, glTF 2.0 §3.5.2) from the front and a little
above, at a distance where the sphere fills the 40° vertical field of view. An asset with a camera is copied as it is.
Usage: gltf_with_camera.py IN.glb OUT.glb"""
import json, math, struct, sys

data = open(sys.argv[1], "rb").read()
magic, version, _ = struct.unpack_from("<III", data, 0)
if magic != 0x46546C67:
    sys.exit("gltf_with_camera: not a binary glTF: " + sys.argv[1])
json_len = struct.unpack_from("<I", data, 12)[0]
doc = json.loads(data[20:20 + json_len])
rest = data[20 + json_len:]  # the BIN chunk, as it is

def mat_mul(a, b):  # column-major 4x4, as glTF stores them
    return [sum(a[r + 4 * k] * b[k + 4 * c] for k in range(4)) for c in range(4) for r in range(4)]

def local(node):
    if "matrix" in node:
        return node["matrix"]
    tx, ty, tz = node.get("translation", [0, 0, 0])
    x, y, z, w = node.get("rotation", [0, 0, 0, 1])
    sx, sy, sz = node.get("scale", [1, 1, 1])
    r = [1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w),
         2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
         2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)]
    return [r[0] * sx, r[1] * sx, r[2] * sx, 0, r[3] * sy, r[4] * sy, r[5] * sy, 0,
            r[6] * sz, r[7] * sz, r[8] * sz, 0, tx, ty, tz, 1]

points = []
def visit(index, parent):
    node = doc["nodes"][index]
    world = mat_mul(parent, local(node))
    for prim in doc["meshes"][node["mesh"]]["primitives"] if "mesh" in node else []:
        acc = doc["accessors"][prim["attributes"]["POSITION"]]
        lo, hi = acc["min"], acc["max"]
        for corner in [(a, b, c) for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])]:
            points.append([sum(world[r + 4 * k] * corner[k] for k in range(3)) + world[r + 12] for r in range(3)])
    for child in node.get("children", []):
        visit(child, world)

if not doc.get("cameras"):
    identity = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    scene = doc["scenes"][doc.get("scene", 0)]
    for n in scene["nodes"]:
        visit(n, identity)
    lo = [min(p[i] for p in points) for i in range(3)]
    hi = [max(p[i] for p in points) for i in range(3)]
    centre = [(a + b) / 2 for a, b in zip(lo, hi)]
    radius = 0.5 * math.dist(lo, hi)
    yfov = math.radians(40)
    distance = radius / math.sin(yfov / 2)
    # From the front (+Z, the glTF forward of an asset) and 20° above; glTF cameras look down their -Z.
    pitch = math.radians(20)
    eye = [centre[0], centre[1] + distance * math.sin(pitch), centre[2] + distance * math.cos(pitch)]
    # Rotation about X by -pitch: the camera's -Z turns towards the centre.
    half = -pitch / 2
    doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": yfov, "znear": 0.01 * radius}}]
    doc["nodes"].append({"name": "bench_camera", "camera": 0, "translation": eye,
                         "rotation": [math.sin(half), 0, 0, math.cos(half)]})
    scene["nodes"].append(len(doc["nodes"]) - 1)

text = json.dumps(doc, separators=(",", ":")).encode()
text += b" " * (-len(text) % 4)
out = struct.pack("<III", magic, version, 12 + 8 + len(text) + len(rest)) + struct.pack("<II", len(text), 0x4E4F534A)
open(sys.argv[2], "wb").write(out + text + rest)
