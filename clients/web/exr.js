// An OpenEXR reader for the images tessera writes, so that the viewer works on the linear radiance itself (exposure,
// tone curve and pixel values in the browser): single-part scan-line files with HALF, FLOAT or UINT channels,
// uncompressed or compressed with RLE, ZIPS or ZIP. The layout is the one of "The OpenEXR File Layout" and
// "Technical Introduction to OpenEXR" (Kainz, Bogart and Stanczyk, openexr.com): magic and version, attributes up
// to an empty name, a table of chunk offsets, then chunks of (y, byte count, data) holding for each scan line the
// channels in the header's (alphabetical) order. Zlib streams are inflated by the browser's DecompressionStream.
// Tiled, deep, multi-part and lossy (PIZ, PXR24, B44, DWA) files are refused with a message: tessera does not
// write them.

const MAGIC = 20000630;
const COMPRESSION = ["none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab"];
const LINES_PER_CHUNK = { none: 1, rle: 1, zips: 1, zip: 16 };
const BYTES = [4, 2, 4]; // UINT, HALF, FLOAT

export class ExrError extends Error {}

// IEEE 754 binary16 to a number.
const HALF = (() => {
  const table = new Float32Array(65536);
  for (let h = 0; h < 65536; ++h) {
    const sign = h & 0x8000 ? -1 : 1;
    const exp = (h >> 10) & 0x1f;
    const frac = h & 0x3ff;
    if (exp === 0) table[h] = sign * frac * 2 ** -24;
    else if (exp === 31) table[h] = frac ? NaN : sign * Infinity;
    else table[h] = sign * (1 + frac / 1024) * 2 ** (exp - 15);
  }
  return table;
})();

function readHeader(view) {
  let at = 0;
  const bytes = new Uint8Array(view.buffer, view.byteOffset, view.byteLength);
  const need = (n) => {
    if (at + n > view.byteLength) throw new ExrError("the file ends inside its header");
  };
  const cstring = () => {
    const end = bytes.indexOf(0, at);
    if (end < 0 || end - at > 255) throw new ExrError("a header name is not terminated");
    const s = new TextDecoder().decode(bytes.subarray(at, end));
    at = end + 1;
    return s;
  };
  need(8);
  if (view.getInt32(0, true) !== MAGIC) throw new ExrError("not an OpenEXR file");
  const flags = view.getUint32(4, true);
  if (flags & 0x200) throw new ExrError("tiled OpenEXR files are not supported by the viewer");
  if (flags & 0x1800) throw new ExrError("deep or multi-part OpenEXR files are not supported by the viewer");
  at = 8;
  const header = {};
  for (;;) {
    need(1);
    const name = cstring();
    if (!name) break;
    const type = cstring();
    need(4);
    const size = view.getInt32(at, true);
    at += 4;
    if (size < 0) throw new ExrError(`attribute ${name} has a negative size`);
    need(size);
    const start = at;
    if (type === "chlist") {
      const channels = [];
      while (bytes[at] !== 0 && at < start + size) {
        const cname = cstring();
        const [type, xs, ys] = [0, 8, 12].map((o) => view.getInt32(at + o, true));
        channels.push({ name: cname, type, xs, ys });
        at += 16;
      }
      header[name] = channels;
    } else if (type === "compression" || type === "lineOrder") {
      header[name] = bytes[at];
    } else if (type === "box2i") {
      header[name] = [0, 4, 8, 12].map((o) => view.getInt32(at + o, true));
    } else if (type === "string" && name.startsWith("cryptomatte/")) {
      // Cryptomatte's metadata, cryptomatte/<key>/<field> (name, hash, conversion, manifest): by key.
      const [, key, field] = name.split("/");
      ((header.cryptomatte ??= {})[key] ??= {})[field] = new TextDecoder().decode(bytes.subarray(at, at + size));
    }
    at = start + size;
  }
  header.end = at;
  return header;
}

async function inflate(bytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

// RLE of ImfRle: a signed count byte, then -count literal bytes or one byte repeated count + 1 times.
function unRle(src, size) {
  const out = new Uint8Array(size);
  let i = 0;
  let o = 0;
  while (i < src.length) {
    const n = (src[i] << 24) >> 24;
    i += 1;
    if (n < 0) {
      if (o - n > size || i - n > src.length) throw new ExrError("an RLE chunk overflows");
      out.set(src.subarray(i, i - n), o);
      i -= n;
      o -= n;
    } else {
      if (o + n + 1 > size || i >= src.length) throw new ExrError("an RLE chunk overflows");
      out.fill(src[i], o, o + n + 1);
      i += 1;
      o += n + 1;
    }
  }
  if (o !== size) throw new ExrError("an RLE chunk is short");
  return out;
}

// RLE and ZIP store the bytes as differences (a predictor), the even-indexed bytes before the odd ones.
function unPredict(t) {
  for (let i = 1; i < t.length; ++i) t[i] = (t[i - 1] + t[i] - 128) & 0xff;
  const out = new Uint8Array(t.length);
  const half = (t.length + 1) >> 1;
  for (let i = 0, a = 0, b = half; i < t.length; ++i) out[i] = i & 1 ? t[b++] : t[a++];
  return out;
}

// The order a layer's channels are read out in: R, G, B (as the beauty), then the others by name (X, Y, Z; U, V).
const channelRank = (c) => ("RGB".includes(c) && c.length === 1 ? "RGB".indexOf(c) : 3);
const byChannel = (a, b) => channelRank(a) - channelRank(b) || (a < b ? -1 : a > b ? 1 : 0);

// Decodes an EXR (an ArrayBuffer). Returns { width, height, rgb: Float32Array of width * height * 3 linear values,
// channels: the names found, layers }. A grey image (Y, or R alone) fills all three; other channels (A, Z...) are
// not in rgb. layers: each layer of channels named <layer>.<channel> (a render pass, "depth.Z"), by its name:
// { channels: ["Z"], values: Float32Array of width * height * channels.length, pixel by pixel }.
export async function decodeExr(buffer) {
  const view = new DataView(buffer);
  const h = readHeader(view);
  const channels = h.channels;
  if (!channels?.length) throw new ExrError("the header has no channels");
  const compression = COMPRESSION[h.compression] ?? `#${h.compression}`;
  const lines = LINES_PER_CHUNK[compression];
  if (!lines) throw new ExrError(`${compression} compression is not supported by the viewer`);
  if (!h.dataWindow) throw new ExrError("the header has no dataWindow");
  const [x0, y0, x1, y1] = h.dataWindow;
  const width = x1 - x0 + 1;
  const height = y1 - y0 + 1;
  if (!(width > 0 && height > 0 && width * height <= 2 ** 26)) throw new ExrError(`bad data window ${h.dataWindow}`);
  for (const c of channels) {
    if (!(c.type in BYTES)) throw new ExrError(`channel ${c.name} has an unknown pixel type ${c.type}`);
    if (c.xs !== 1 || c.ys !== 1) throw new ExrError(`channel ${c.name} is subsampled`);
  }
  const lineBytes = channels.reduce((n, c) => n + BYTES[c.type] * width, 0);
  const rgb = new Float32Array(width * height * 3);
  const slot = { R: 0, G: 1, B: 2, Y: 0 }; // Y: a luminance-only (grey) image
  // Each layered channel's place: its layer's array and its index in a pixel there.
  const layers = {};
  const place = new Map();
  for (const c of channels) {
    const dot = c.name.lastIndexOf(".");
    if (dot <= 0) continue;
    const name = c.name.slice(0, dot);
    (layers[name] ??= { channels: [] }).channels.push(c.name.slice(dot + 1));
  }
  for (const [name, layer] of Object.entries(layers)) {
    layer.channels.sort(byChannel);
    layer.values = new Float32Array(width * height * layer.channels.length);
    layer.channels.forEach((ch, i) => place.set(`${name}.${ch}`, { layer, i, n: layer.channels.length }));
  }
  const chunks = Math.ceil(height / lines);
  const tableEnd = h.end + 8 * chunks;
  if (tableEnd > buffer.byteLength) throw new ExrError("the file ends inside its offset table");
  for (let k = 0; k < chunks; ++k) {
    const offset = Number(view.getBigUint64(h.end + 8 * k, true));
    if (offset < tableEnd || offset + 8 > buffer.byteLength) throw new ExrError(`chunk ${k} lies outside the file`);
    const y = view.getInt32(offset, true) - y0;
    const size = view.getInt32(offset + 4, true);
    if (size < 0 || offset + 8 + size > buffer.byteLength) throw new ExrError(`chunk ${k} is cut short`);
    if (y < 0 || y >= height || y % lines) throw new ExrError(`chunk ${k} has a bad line number`);
    const count = Math.min(lines, height - y);
    const expected = count * lineBytes;
    let data = new Uint8Array(buffer, offset + 8, size);
    // A chunk that would not shrink is stored as it is.
    if (compression !== "none" && size < expected) {
      if (compression === "rle") data = unRle(data, expected);
      else {
        try {
          data = await inflate(data);
        } catch (e) {
          throw new ExrError(`chunk ${k} does not inflate (${e.message})`);
        }
      }
      data = unPredict(data);
    }
    if (data.length !== expected) throw new ExrError(`chunk ${k} holds ${data.length} bytes, not ${expected}`);
    const d = new DataView(data.buffer, data.byteOffset, data.byteLength);
    let at = 0;
    for (let line = 0; line < count; ++line) {
      const row = (y + line) * width * 3;
      for (const c of channels) {
        const s = slot[c.name];
        const p = place.get(c.name);
        if (s !== undefined || p) {
          const read = c.type === 1 ? (o) => HALF[d.getUint16(o, true)] : c.type === 2 ? (o) => d.getFloat32(o, true)
            : (o) => d.getUint32(o, true);
          if (s !== undefined) for (let x = 0; x < width; ++x) rgb[row + 3 * x + s] = read(at + x * BYTES[c.type]);
          else {
            const start = (y + line) * width * p.n + p.i;
            for (let x = 0; x < width; ++x) p.layer.values[start + p.n * x] = read(at + x * BYTES[c.type]);
          }
        }
        at += width * BYTES[c.type];
      }
    }
  }
  const names = channels.map((c) => c.name);
  if (!names.includes("G") || !names.includes("B")) {
    for (let i = 0; i < rgb.length; i += 3) {
      if (!names.includes("G")) rgb[i + 1] = rgb[i];
      if (!names.includes("B")) rgb[i + 2] = rgb[i];
    }
  }
  return { width, height, rgb, channels: names, layers, cryptomatte: cryptomattes(h.cryptomatte, layers) };
}

// The Cryptomatte types of a file (Cryptomatte specification 1.1): by type name ("CryptoObject"), { names: the
// manifest as a Map from an id's float bits to its name, ranks: the layers <type>00, <type>01, ... (R, G, B, A: id,
// coverage, id, coverage) }. Types without layers are left out; a manifest that is not JSON names nothing.
function cryptomattes(metadata, layers) {
  const out = {};
  for (const meta of Object.values(metadata || {})) {
    const type = meta.name;
    if (!type) continue;
    const ranks = [];
    const rank = (k) => layers[`${type}${String(k).padStart(2, "0")}`];
    for (let k = 0; rank(k); ++k) ranks.push(rank(k));
    if (!ranks.length) continue;
    const names = new Map();
    try {
      for (const [name, hex] of Object.entries(JSON.parse(meta.manifest || "{}")))
        names.set(parseInt(hex, 16) >>> 0, name);
    } catch {
      // Mattes still read without names.
    }
    out[type] = { names, ranks };
  }
  return out;
}

// The Cryptomatte type a render pass holds: crypto_object is CryptoObject's (the type name in snake case), or null.
export function cryptomatteOfPass(image, pass) {
  for (const [type, matte] of Object.entries(image.cryptomatte || {}))
    if (type.replace(/([a-z0-9])([A-Z])/g, "$1_$2").toLowerCase() === pass) return matte;
  return null;
}

// The ids pixel i holds in a Cryptomatte type, by rank: [{ name, coverage }], names from the manifest (else the id's
// bits in hexadecimal), ranks of coverage 0 left out.
export function cryptomatteAt(matte, i) {
  const bits = new Uint32Array(1);
  const asFloat = new Float32Array(bits.buffer);
  const out = [];
  for (const layer of matte.ranks) {
    const n = layer.channels.length;
    const at = n * i;
    for (const [idChannel, coverageChannel] of [["R", "G"], ["B", "A"]]) {
      const id = layer.channels.indexOf(idChannel);
      const coverage = layer.channels.indexOf(coverageChannel);
      if (id < 0 || coverage < 0 || !(layer.values[at + coverage] > 0)) continue;
      asFloat[0] = layer.values[at + id];
      const name = matte.names.get(bits[0]) ?? bits[0].toString(16).padStart(8, "0");
      out.push({ name, coverage: layer.values[at + coverage] });
    }
  }
  return out;
}
