#!/usr/bin/env python3
"""Writes large valid glTF assets into DIR for bench/upload_memory.sh: a grid mesh of N x N vertices (float positions
and normals, uint32 triangles; about 48 N^2 bytes) as big.glb, as big.gltf beside big.bin, and as embedded.gltf with
its buffer as a base64 data: URI (N scaled down so that the file is about as large), and textured.glb: a quad whose
texture is one PNG of noise (incompressible) of about as many bytes, in the .glb's buffer."""
import array, base64, json, math, os, struct, sys, zlib


def grid(n):
    pos, nrm, idx = array.array('f'), array.array('f'), array.array('I')
    for j in range(n):
        for i in range(n):
            pos.extend((i / (n - 1) - 0.5, j / (n - 1) - 0.5, 0.0))
    nrm.extend((0.0, 0.0, 1.0) * (n * n))
    for j in range(n - 1):
        for a in range(j * n, j * n + n - 1):
            idx.extend((a, a + 1, a + n, a + 1, a + n + 1, a + n))
    return pos.tobytes() + nrm.tobytes() + idx.tobytes(), n * n, len(idx)


def document(n, length, count, uri=None):
    half = n * n * 12
    buffer = {"byteLength": length}
    if uri:
        buffer["uri"] = uri
    return {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2}]}],
            "buffers": [buffer],
            "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": half},
                            {"buffer": 0, "byteOffset": half, "byteLength": half},
                            {"buffer": 0, "byteOffset": 2 * half, "byteLength": length - 2 * half}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": n * n, "type": "VEC3",
                           "min": [-0.5, -0.5, 0], "max": [0.5, 0.5, 0]},
                          {"bufferView": 1, "componentType": 5126, "count": n * n, "type": "VEC3"},
                          {"bufferView": 2, "componentType": 5125, "count": count, "type": "SCALAR"}]}


def padded(b, fill):
    return b + fill * ((4 - len(b) % 4) % 4)


def png(width, height):
    rows = b''.join(b'\0' + os.urandom(width * 4) for _ in range(height))

    def chunk(kind, data):
        return struct.pack('>I', len(data)) + kind + data + struct.pack('>I', zlib.crc32(kind + data))
    return (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', width, height, 8, 6, 0, 0, 0)) +
            chunk(b'IDAT', zlib.compress(rows, 1)) + chunk(b'IEND', b''))


def textured_glb(megabytes):
    side = int(math.sqrt(megabytes * 1e6 / 4))
    image = padded(png(side, side), b'\0')
    quad = array.array('f', [-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0]).tobytes()
    uv = array.array('f', [0, 1, 1, 1, 1, 0, 0, 0]).tobytes()
    indices = array.array('I', [0, 1, 2, 0, 2, 3]).tobytes()
    binary = quad + uv + indices + image
    views = [(0, 48), (48, 32), (80, 24), (104, len(image))]
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
           "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
           "textures": [{"source": 0}], "images": [{"bufferView": 3, "mimeType": "image/png"}],
           "buffers": [{"byteLength": len(binary)}],
           "bufferViews": [{"buffer": 0, "byteOffset": o, "byteLength": n} for o, n in views],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                          "min": [-1, -1, 0], "max": [1, 1, 0]},
                         {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                         {"bufferView": 2, "componentType": 5125, "count": 6, "type": "SCALAR"}]}
    return glb(doc, binary)


def glb(doc, binary):
    text = padded(json.dumps(doc).encode(), b' ')
    chunk = padded(binary, b'\0')
    return (struct.pack('<III', 0x46546C67, 2, 12 + 8 + len(text) + 8 + len(chunk)) +
            struct.pack('<II', len(text), 0x4E4F534A) + text + struct.pack('<II', len(chunk), 0x004E4942) + chunk)


def main():
    out, megabytes = sys.argv[1], float(sys.argv[2])
    os.makedirs(out, exist_ok=True)
    n = int(math.sqrt(megabytes * 1e6 / 48))
    binary, _, count = grid(n)
    with open(os.path.join(out, 'big.glb'), 'wb') as f:
        f.write(glb(document(n, len(binary), count), binary))
    with open(os.path.join(out, 'big.gltf'), 'w') as f:
        json.dump(document(n, len(binary), count, 'big.bin'), f)
    with open(os.path.join(out, 'big.bin'), 'wb') as f:
        f.write(binary)
    m = int(n * math.sqrt(3 / 4))  # base64 takes 4 characters for 3 bytes
    binary, _, count = grid(m)
    uri = 'data:application/octet-stream;base64,' + base64.b64encode(binary).decode()
    with open(os.path.join(out, 'embedded.gltf'), 'w') as f:
        json.dump(document(m, len(binary), count, uri), f)
    with open(os.path.join(out, 'textured.glb'), 'wb') as f:
        f.write(textured_glb(megabytes))


main()
