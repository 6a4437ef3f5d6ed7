// A minimal PNG reader for the tests: 8-bit grey, grey+alpha, RGB and RGBA, not
// interlaced (what OpenImageIO writes for volcast's frames and volcast-render). Returns
// {width, height, channels, data: Uint8Array} with the file's own channels. No
// dependencies: node:zlib inflates.
import { inflateSync } from "node:zlib";

const SIGNATURE = [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a];
const CHANNELS = { 0: 1, 2: 3, 4: 2, 6: 4 };   // colour type → channels

export function decodePng(buf) {
  const bytes = buf instanceof Uint8Array ? buf : new Uint8Array(buf);
  if (!SIGNATURE.every((b, i) => bytes[i] === b)) throw new Error("png: bad signature");
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  let pos = 8, width = 0, height = 0, channels = 0;
  const idat = [];
  while (pos + 8 <= bytes.length) {
    const len = view.getUint32(pos);
    const type = String.fromCharCode(...bytes.subarray(pos + 4, pos + 8));
    const body = bytes.subarray(pos + 8, pos + 8 + len);
    if (type === "IHDR") {
      width = view.getUint32(pos + 8);
      height = view.getUint32(pos + 12);
      const depth = body[8], colour = body[9], interlace = body[12];
      if (depth !== 8) throw new Error(`png: bit depth ${depth} not supported`);
      if (!(colour in CHANNELS)) throw new Error(`png: colour type ${colour} not supported`);
      if (interlace !== 0) throw new Error("png: interlaced images not supported");
      channels = CHANNELS[colour];
    } else if (type === "IDAT") {
      idat.push(body);
    } else if (type === "IEND") {
      break;
    }
    pos += 12 + len;
  }
  if (!width || !idat.length) throw new Error("png: no IHDR or IDAT");
  const raw = inflateSync(Buffer.concat(idat.map((b) => Buffer.from(b))));
  const stride = width * channels;
  if (raw.length < height * (stride + 1)) throw new Error("png: image data too short");
  const out = new Uint8Array(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    const row = out.subarray(y * stride, (y + 1) * stride);
    const prev = y > 0 ? out.subarray((y - 1) * stride, y * stride) : null;
    for (let x = 0; x < stride; x++) {
      const a = x >= channels ? row[x - channels] : 0;
      const b = prev ? prev[x] : 0;
      const c = prev && x >= channels ? prev[x - channels] : 0;
      let v = line[x];
      switch (filter) {
        case 0: break;
        case 1: v += a; break;
        case 2: v += b; break;
        case 3: v += (a + b) >> 1; break;
        case 4: {
          const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
          v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
          break;
        }
        default: throw new Error(`png: filter ${filter} on row ${y}`);
      }
      row[x] = v & 0xff;
    }
  }
  return { width, height, channels, data: out };
}

// RGB8 composited over black, as the viewer shows it and as volcast-render writes PNGs
// (premultiplied colour, rounded): straight RGBA becomes round(c · a / 255); RGB stays.
export function overBlack(img) {
  if (img.channels === 3) return img.data;
  if (img.channels !== 4) throw new Error(`png: ${img.channels} channels; expected RGB or RGBA`);
  const n = img.width * img.height, out = new Uint8Array(n * 3);
  for (let i = 0; i < n; i++) {
    const a = img.data[i * 4 + 3];
    for (let k = 0; k < 3; k++) out[i * 3 + k] = Math.round((img.data[i * 4 + k] * a) / 255);
  }
  return out;
}

// Per-channel differences between two 8-bit images of one size and layout.
export function compareBytes(a, b) {
  let max = 0, sum = 0, over1 = 0;
  for (let i = 0; i < a.length; i++) {
    const d = Math.abs(a[i] - b[i]);
    if (d > max) max = d;
    if (d > 1) over1++;
    sum += d * d;
  }
  return { maxDiff: max, rmse: Math.sqrt(sum / a.length) / 255, channelsOver1: over1 };
}
