// The web client's EXR reader (clients/web/exr.js) against OpenImageIO: files written by oiiotool in every layout
// the reader takes (HALF and FLOAT; none, RLE, ZIPS and ZIP, compressible and not, so that both the inflated and the
// stored-as-is chunks are read; a grey image) and by tessera-render itself (its render passes' layers too) decode to
// exactly the values `oiiotool --dumpdata` prints; a cut or garbled file and a compression it does not take are
// refused with an ExrError.
//
// node --test tests/browser/exr_decoder_test.mjs   with   TESSERA_RENDER=path/to/tessera-render   (CTest passes it)
import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { after, test } from "node:test";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, "../..");
const { cryptomatteAt, cryptomatteOfPass, decodeExr, ExrError } = await import(path.join(repo, "clients/web/exr.js"));
const RENDER = process.env.TESSERA_RENDER || path.join(repo, "build/clients/cli/tessera-render");
const tmp = fs.mkdtempSync(path.join(os.tmpdir(), "tessera-exr-"));
after(() => fs.rmSync(tmp, { recursive: true, force: true }));

const oiiotool = (...args) => execFileSync("oiiotool", args, { encoding: "utf8", maxBuffer: 64 << 20 });
const arrayBuffer = (file) => {
  const b = fs.readFileSync(file);
  return b.buffer.slice(b.byteOffset, b.byteOffset + b.length);
};

// One channel of an EXR as a file of its own.
function oneChannel(file, channel) {
  const one = path.join(tmp, `one-${channel}.exr`);
  oiiotool(file, "--ch", channel, "-o", one);
  return one;
}

// A value as --dumpdata prints it ("inf" where a depth pass found no surface).
const value = (t) => (/^[-+]?inf/i.test(t) ? (t[0] === "-" ? -Infinity : Infinity) : Number(t));
// Every pixel as OpenImageIO reads it: "Pixel (x, y): r g b" lines, a grey image's one value repeated.
function reference(file) {
  const values = [];
  for (const m of oiiotool("--dumpdata", file).matchAll(/Pixel \((\d+), (\d+)\):((?: \S+)+)/g)) {
    const v = m[3].trim().split(/\s+/).map(value);
    values.push(...(v.length === 1 ? [v[0], v[0], v[0]] : v.slice(0, 3)));
  }
  return values;
}

async function agrees(file) {
  const img = await decodeExr(arrayBuffer(file));
  const want = reference(file);
  assert.equal(img.rgb.length, want.length, `${path.basename(file)}: ${img.width}x${img.height}`);
  for (let i = 0; i < want.length; ++i) {
    // --dumpdata prints 9 decimals: as exact as a half, and within 5e-10 of a float in [0, 4].
    if (Math.abs(img.rgb[i] - want[i]) > 1e-9 + 1e-7 * Math.abs(want[i]))
      assert.fail(`${path.basename(file)}: value ${i} (pixel ${Math.floor(i / 3)}) is ${img.rgb[i]}, not ${want[i]}`);
  }
  return img;
}

for (const type of ["half", "float"]) {
  for (const compression of ["none", "rle", "zips", "zip"]) {
    test(`${type} ${compression}`, async () => {
      // A gradient compresses; noise does not, and is then stored as it is. 37 x 23 spans two 16-line ZIP chunks.
      for (const [name, pattern] of [
        ["gradient", "fill:top=0.1,0.2,0.3:bottom=3.9,0.5,0.25"],
        ["noise", "noise:type=uniform:min=0:max=4"],
      ]) {
        const file = path.join(tmp, `${name}-${type}-${compression}.exr`);
        oiiotool("--pattern", pattern, "37x23", "3", "-d", type, "--compression", compression, "-o", file);
        const img = await agrees(file);
        assert.deepEqual([img.width, img.height], [37, 23]);
      }
    });
  }
}

test("a grey image fills all three channels", async () => {
  const file = path.join(tmp, "grey.exr");
  oiiotool("--pattern", "fill:left=0.25:right=2", "9x5", "1", "-d", "half", "--compression", "zip", "-o", file);
  const img = await agrees(file);
  assert.deepEqual(img.channels, ["Y"]);
});

test("tessera-render's EXR, half and float", async () => {
  assert.ok(fs.existsSync(RENDER), `no tessera-render at ${RENDER}`);
  for (const precision of ["half", "float"]) {
    const job = path.join(tmp, `job-${precision}.json`);
    fs.writeFileSync(
      job,
      JSON.stringify({
        kind: "material",
        material: { type: "conductor", metal: "copper", roughness: 0.2 },
        render: { width: 40, height: 34, spp: 2, exr_precision: precision },
      }),
    );
    const out = path.join(tmp, `render-${precision}.exr`);
    execFileSync(RENDER, ["render", job, "-o", out, "-q"]);
    const img = await agrees(out);
    assert.ok(img.rgb.some((v) => v > 0), "the render is not black");
  }
});

// Render passes are layers <pass>.<channel> (half or float beside each other): each decodes to OpenImageIO's values,
// its channels R, G, B first and the rest by name, and the beauty stays R, G, B.
test("tessera-render's EXR with render passes: every layer", async () => {
  const job = path.join(tmp, "job-aovs.json");
  const aovs = ["albedo", "normal", "depth", "uv", "object_id", "variance"];
  fs.writeFileSync(
    job,
    JSON.stringify({
      kind: "material",
      material: { type: "conductor", metal: "copper", roughness: 0.2 },
      render: { width: 24, height: 18, spp: 4, aovs, denoise: "none" },
    }),
  );
  const out = path.join(tmp, "render-aovs.exr");
  execFileSync(RENDER, ["render", job, "-o", out, "-q"]);
  const img = await decodeExr(arrayBuffer(out));
  assert.deepEqual(Object.keys(img.layers).sort(), [...aovs].sort());
  const order = { albedo: ["R", "G", "B"], normal: ["X", "Y", "Z"], depth: ["Z"], uv: ["U", "V"],
    object_id: ["X"], variance: ["R", "G", "B"] };
  const beauty = { channels: ["R", "G", "B"], values: img.rgb };
  for (const [name, layer] of [["", beauty], ...Object.entries(img.layers)]) {
    if (name) assert.deepEqual(layer.channels, order[name], `${name}'s channels`);
    const n = layer.channels.length;
    layer.channels.forEach((c, k) => {
      const channel = name ? `${name}.${c}` : c;
      const one = path.join(tmp, `aov-${channel}.exr`);
      oiiotool(out, "--ch", channel, "-o", one);
      const want = reference(one);
      for (let i = 0; i < img.width * img.height; ++i) {
        const got = layer.values[n * i + k];
        const w = want[3 * i];
        if (!(got === w || Math.abs(got - w) <= 1e-9 + 1e-7 * Math.abs(w)))
          assert.fail(`${channel} of pixel ${i} is ${got}, not ${w}`);
      }
    });
  }
});

// Cryptomatte passes: the manifests of the header name the ids, and each pixel's ranks read out as names with their
// coverage, rank 0's coverage being OpenImageIO's CryptoObject00.G.
test("tessera-render's EXR with Cryptomatte passes: names and coverage by rank", async () => {
  const out = path.join(tmp, "render-crypto.exr");
  execFileSync(RENDER, ["render", path.join(repo, "proto/examples/cornell.json"), "--width", "20", "--height", "16",
    "--spp", "8", "--aov", "crypto_object", "--aov", "crypto_material", "-o", out, "-q"]);
  const img = await decodeExr(arrayBuffer(out));
  assert.deepEqual(Object.keys(img.cryptomatte).sort(), ["CryptoMaterial", "CryptoObject"]);
  const objects = cryptomatteOfPass(img, "crypto_object");
  assert.equal(objects, img.cryptomatte.CryptoObject);
  assert.equal(cryptomatteOfPass(img, "crypto_material"), img.cryptomatte.CryptoMaterial);
  assert.equal(cryptomatteOfPass(img, "albedo"), null);
  assert.equal(objects.ranks.length, 3);
  assert.deepEqual([...objects.names.values()].sort(), [0, 1, 2, 3, 4, 5, 6, 7].map((i) => `objects[${i}]`));
  assert.deepEqual([...img.cryptomatte.CryptoMaterial.names.values()].sort(), ["green", "light", "red", "white"]);
  // (--dumpdata prints ids, floats of any magnitude, to 9 decimals: only the coverage is compared with it.)
  const coverage = reference(oneChannel(out, "CryptoObject00.G"));
  const names = new Set(objects.names.values());
  let seen = 0;
  for (let i = 0; i < img.width * img.height; ++i) {
    const ranked = cryptomatteAt(objects, i);
    if (coverage[3 * i] === 0) {
      assert.deepEqual(ranked, [], `pixel ${i} sees nothing`);
      continue;
    }
    ++seen;
    const total = ranked.reduce((sum, e) => sum + e.coverage, 0);
    assert.ok(total <= 1 + 1e-6, `pixel ${i}'s coverage sums to ${total}`);
    // Every id found is one the manifest names (an id decoded to other bits would read out as hexadecimal).
    for (const e of ranked) assert.ok(names.has(e.name), `pixel ${i}: ${e.name}`);
    assert.ok(Math.abs(ranked[0].coverage - coverage[3 * i]) <= 1e-6, `pixel ${i}'s rank 0 coverage`);
  }
  assert.ok(seen > (img.width * img.height) / 2, `${seen} pixels see an object`);
});

test("a cut or garbled file and an unsupported compression are refused with a message", async () => {
  const file = path.join(tmp, "gradient-half-zip.exr");
  const whole = new Uint8Array(arrayBuffer(file));
  for (const n of [0, 4, 8, 40, 300, whole.length - 200, whole.length - 1]) {
    await assert.rejects(decodeExr(whole.slice(0, n).buffer), ExrError, `the first ${n} bytes`);
  }
  const garbled = whole.slice();
  for (let i = whole.length - 120; i < whole.length - 20; ++i) garbled[i] ^= 0x5a;
  await assert.rejects(decodeExr(garbled.buffer), ExrError, "a garbled chunk");
  const piz = path.join(tmp, "piz.exr");
  oiiotool("--pattern", "noise", "8x8", "3", "--compression", "piz", "-o", piz);
  await assert.rejects(decodeExr(arrayBuffer(piz)), /piz compression is not supported/);
});
