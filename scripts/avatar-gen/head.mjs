//! The avatar's design in code: head, eyes, lids, brows, mouth, hair, neck and shoulders, and every morph target.
// @ts-check
//
// Units are metres, +y up, the avatar looks along +z (towards the viewer), its left is +x. Shapes follow the 2D
// face (web/js/avatar/face.js): its palette, its proportions (eyes at the skull's centre line, nose tip 36 mm and
// mouth 62 mm below them, large stylised eyes, a side-swept fringe and a bob).
//
// Morph targets are displacement fields evaluated at each vertex's rest position (plus a little per-vertex
// information such as how much a vertex belongs to the jaw). Parts that touch, such as the lips, the mouth's
// inside and the skin around them, are moved by the same fields, so they stay joined in every pose. Visemes are
// recipes over a few elementary fields (jaw, width, rounding, pressing, lips parted, tongue), with the amounts
// of the 2D face's mouth shapes (web/js/avatar/visemes.js).

import {
  Part, normals, frontZ, add, sub, scale, lerp, clamp, smoothstep, linear, mix3,
} from "./mesh.mjs";

/** @typedef {import("./mesh.mjs").V3} V3 */

// ---- proportions ---------------------------------------------------------------------------------------------

/** Where the head turns: the top of the neck, in the avatar's frame (the Head node's translation). */
export const HEAD_PIVOT = /** @type {V3} */ ([0, 0.1, 0]);
/** The skull's centre in the head's frame, and its half-width, half-height and half-depth. */
const C = /** @type {V3} */ ([0, 0.055, 0.008]);
const A = 0.08;
const B = 0.093;
const D = 0.09;

const EYE_R = 0.0165; // eyeball radius: stylised, large eyes like the 2D face's
const EYE_X = 0.034;
const EYE_Y = C[1] + 0.003;
const EYE_OUT = 0.0056; // how far the eyeball's front stands out of the skin
const LID_R = EYE_R * 1.08;
const MOUTH_Y = C[1] - 0.059;
const MOUTH_W = 0.0195; // half-width of the lips
const UPPER_LIP = 0.0056;
const LOWER_LIP = 0.0074;
const JAW_MAX_RAD = 0.16; // jaw = 1 opens the lips by about 18 mm
const JAW_HINGE = /** @type {V3} */ ([0, C[1] - 0.012, C[2] - 0.025]);

// ---- palette (the 2D face's) ---------------------------------------------------------------------------------

const SKIN = linear(0xf5cdb0);
const SKIN_SHADE = linear(0xe2a888);
const BLUSH = linear(0xeb6e78);
const LIP_UP = linear(0xc4647a);
const LIP_LOW = linear(0xd7798a);
const LIP_IN = linear(0x9c4257);
const LIP_LINE = linear(0x7c2f41);
const HAIR_BASE = linear(0x3a2634);
const HAIR_MID = linear(0x5a3b4e);
const IRIS_IN = linear(0x49b3b0);
const IRIS_OUT = linear(0x1d5e68);
const IRIS_RING = linear(0x0f3238);
const PUPIL = linear(0x0b1114);
const CLOTH = linear(0x1c2b44);
const CLOTH_LIGHT = linear(0x2b4266);
const COLLAR = linear(0x5fd4c4);
const WHITE = /** @type {V3} */ ([1, 1, 1]);

export const MATERIALS = [
  { name: "skin", baseColor: [1, 1, 1], roughness: 0.62 },
  { name: "lips", baseColor: [1, 1, 1], roughness: 0.38, doubleSided: true },
  { name: "mouth", baseColor: linear(0x3a0e18), roughness: 0.9, doubleSided: true },
  { name: "teeth", baseColor: [1, 1, 1], roughness: 0.3, doubleSided: true },
  { name: "tongue", baseColor: linear(0xc9566a), roughness: 0.5 },
  { name: "sclera", baseColor: [1, 1, 1], roughness: 0.18 },
  { name: "iris", baseColor: [1, 1, 1], roughness: 0.15 },
  { name: "hair", baseColor: [1, 1, 1], roughness: 0.42, doubleSided: true },
  { name: "cloth", baseColor: [1, 1, 1], roughness: 0.82 },
  { name: "brows", baseColor: linear(0x35212c), roughness: 0.7 },
  { name: "lashes", baseColor: linear(0x1a1016), roughness: 0.6, doubleSided: true },
  // Lids are thin shells seen from both sides as they move (their rim turns inwards).
  { name: "lids", baseColor: [1, 1, 1], roughness: 0.62, doubleSided: true },
  { name: "catchlight", baseColor: [1, 1, 1], roughness: 1, emissive: [0.85, 0.85, 0.85] },
];
const M = Object.fromEntries(MATERIALS.map((m, i) => [m.name, i]));

export const VISEME_NAMES = ["sil", "PP", "FF", "TH", "DD", "kk", "CH", "SS", "nn", "RR", "aa", "E", "I", "O", "U"];

/** The 2D face's mouth shapes (web/js/avatar/visemes.js), the amounts each viseme's morph target is made of. */
const SHAPES = {
  sil: { jaw: 0.0, mouthWidth: 1.0, round: 0.0, teeth: 0.6, tongue: 0.0, lipPress: 0.0 },
  PP: { jaw: 0.0, mouthWidth: 0.94, round: 0.1, teeth: 0.0, tongue: 0.0, lipPress: 1.0 },
  FF: { jaw: 0.1, mouthWidth: 1.0, round: 0.0, teeth: 1.0, tongue: 0.0, lipPress: 0.4 },
  TH: { jaw: 0.2, mouthWidth: 1.0, round: 0.0, teeth: 0.8, tongue: 1.0, lipPress: 0.0 },
  DD: { jaw: 0.25, mouthWidth: 1.02, round: 0.0, teeth: 0.8, tongue: 0.6, lipPress: 0.0 },
  kk: { jaw: 0.32, mouthWidth: 1.0, round: 0.0, teeth: 0.5, tongue: 0.3, lipPress: 0.0 },
  CH: { jaw: 0.22, mouthWidth: 0.84, round: 0.45, teeth: 1.0, tongue: 0.0, lipPress: 0.0 },
  SS: { jaw: 0.1, mouthWidth: 1.06, round: 0.0, teeth: 1.0, tongue: 0.0, lipPress: 0.0 },
  nn: { jaw: 0.2, mouthWidth: 1.0, round: 0.0, teeth: 0.6, tongue: 0.8, lipPress: 0.0 },
  RR: { jaw: 0.22, mouthWidth: 0.86, round: 0.5, teeth: 0.4, tongue: 0.2, lipPress: 0.0 },
  aa: { jaw: 0.85, mouthWidth: 1.05, round: 0.0, teeth: 0.4, tongue: 0.3, lipPress: 0.0 },
  E: { jaw: 0.5, mouthWidth: 1.14, round: 0.0, teeth: 0.8, tongue: 0.2, lipPress: 0.0 },
  I: { jaw: 0.3, mouthWidth: 1.2, round: 0.0, teeth: 0.9, tongue: 0.1, lipPress: 0.0 },
  O: { jaw: 0.6, mouthWidth: 0.82, round: 0.75, teeth: 0.2, tongue: 0.2, lipPress: 0.0 },
  U: { jaw: 0.3, mouthWidth: 0.72, round: 1.0, teeth: 0.0, tongue: 0.0, lipPress: 0.0 },
};

export const MOUTH_TARGETS = [
  ...VISEME_NAMES.map((v) => `viseme_${v}`),
  "jawOpen", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
];
export const LID_TARGETS = [
  "eyeBlinkLeft", "eyeBlinkRight", "eyeSquintLeft", "eyeSquintRight", "eyeWideLeft", "eyeWideRight",
];
export const BROW_TARGETS = ["browInnerUp", "browDownLeft", "browDownRight", "browOuterUpLeft", "browOuterUpRight"];

// ---- the skull surface ---------------------------------------------------------------------------------------

/** A smooth maximum of `a` and `b` (polynomial, blending over `k`). */
function smax(a, b, k) {
  if (!Number.isFinite(b)) return a;
  const h = Math.max(k - Math.abs(a - b), 0) / k;
  return Math.max(a, b) + (h * h * k) / 4;
}

const gauss = (dx, sx, dy, sy) => Math.exp(-((dx / sx) ** 2) - (dy / sy) ** 2);

/** The face's relief in front (nose, brow ridge, cheekbones, muzzle, chin) at (x, y) relative to the skull centre. */
function relief(x, y) {
  const ax = Math.abs(x);
  // Nose: a ridge that widens and rises from the bridge to a rounded tip, then ends sharply above the lip.
  const tipY = -0.036;
  const k = clamp((0.008 - y) / (0.008 - tipY), 0, 1);
  let profile = y > 0.008 ? 0 : 0.22 + 0.78 * Math.pow(k, 1.4);
  if (y < tipY) profile = Math.exp(-(((y - tipY) / 0.0075) ** 2));
  const sigma = lerp(0.0052, 0.0105, k);
  let z = 0.0115 * profile * Math.exp(-((x / sigma) ** 2));
  z += 0.0024 * gauss(ax - 0.0095, 0.0042, y - (tipY - 0.001), 0.005); // nostril wings
  z += 0.0032 * Math.exp(-(((y - 0.034) / 0.009) ** 2)) * smoothstep(0.066, 0.03, ax); // brow ridge
  z += 0.0042 * gauss(ax - 0.043, 0.015, y + 0.014, 0.014); // cheekbones
  z += 0.0062 * gauss(x, 0.026, y + 0.062, 0.017); // the muzzle the lips sit on
  z += 0.0065 * gauss(x, 0.015, y + 0.09, 0.012); // chin
  z -= 0.0025 * gauss(x, 0.012, y + 0.077, 0.005); // the dip under the lower lip
  return z;
}

/** A point of the skull for azimuth `u` (0 = front, +pi/2 = the avatar's left) and polar angle `v` (0 = top). */
function skull(u, v) {
  const nx = Math.sin(v) * Math.sin(u);
  const ny = Math.cos(v);
  const nz = Math.sin(v) * Math.cos(u);
  const lower = Math.max(0, -ny);
  let x = A * nx * (1 - 0.17 * Math.pow(lower, 1.8));
  const y = B * ny;
  let z = D * nz;
  if (nz > 0) z *= 0.95 - 0.1 * lower * lower;
  else z *= 1.04;
  // The back of the jaw tucks in under the ears.
  if (nz > -0.2) x *= 1 - 0.08 * smoothstep(0.2, 0.9, lower) * smoothstep(-0.2, 0.6, nz);
  const front = smoothstep(0.15, 0.6, nz);
  z += front * relief(x, y);
  return /** @type {V3} */ ([C[0] + x, C[1] + y, C[2] + z]);
}

/** How much a skin point at (x, y, z) belongs to the lower jaw (0..1). */
function skinJawWeight(p) {
  const dx = Math.abs(p[0]);
  const dy = p[1] - MOUTH_Y;
  const line = dy - 0.4 * Math.max(0, dx - 0.02);
  return smoothstep(0.0035, -0.006, line) * smoothstep(C[2] - 0.04, C[2] + 0.02, p[2]);
}

// ---- morph fields --------------------------------------------------------------------------------------------

function rotateX(p, pivot, angle) {
  const y = p[1] - pivot[1];
  const z = p[2] - pivot[2];
  const c = Math.cos(angle);
  const s = Math.sin(angle);
  return /** @type {V3} */ ([p[0], pivot[1] + y * c - z * s, pivot[2] + y * s + z * c]);
}

/** Elementary mouth fields: each gives the displacement of a vertex at rest position `p` with `info`. */
const FIELDS = {
  jaw(p, info, amount) {
    const w = info.jaw ?? 0;
    const d = scale(sub(rotateX(p, JAW_HINGE, JAW_MAX_RAD * amount), p), w);
    if (info.rigid) return d;
    // The corners draw in as the mouth opens, which rounds the opening into an oval.
    const corner = Math.min(1, (p[0] / MOUTH_W) ** 2) * gauss(p[0], 0.03, p[1] - MOUTH_Y, 0.01);
    return add(d, [-p[0] * 0.2 * amount * corner, 0, 0]);
  },
  /** Corners out (k > 0) or in (k < 0), following the face's curve back. */
  wide(p, info, k) {
    if (info.rigid) return [0, 0, 0];
    const dx = p[0] / MOUTH_W;
    const f = gauss(p[0], 0.036, p[1] - MOUTH_Y, 0.02);
    return [0.0045 * k * dx * f, 0, -0.0016 * k * dx * dx * f];
  },
  /** Lips rounded and pushed forward. */
  round(p, info, k) {
    if (info.rigid) return [0, 0, 0];
    const dx = p[0] / MOUTH_W;
    const f = gauss(p[0], 0.034, p[1] - MOUTH_Y, 0.02);
    const g = gauss(p[0], 0.026, p[1] - MOUTH_Y, 0.013);
    const lip = info.lip ? 1 : 0.5;
    // Rounding also gathers the lips vertically towards the middle, which makes the opening an "o".
    const dy = (p[1] - MOUTH_Y) * -0.18 * lip * g;
    return [-0.0072 * k * dx * f, dy * k, 0.0048 * k * g * lip];
  },
  /** Lips pressed together: thinner, rolled in a little. */
  press(p, info, k) {
    if (!info.lip) return [0, 0, 0];
    return [0, -0.35 * (p[1] - MOUTH_Y) * k, -0.0012 * k];
  },
  /** Lips parted to show the teeth: the upper lip lifts, the lower drops a little. */
  part(p, info, k) {
    if (!info.lip && !info.lipSkin) return [0, 0, 0];
    const up = info.upper ?? (p[1] > MOUTH_Y ? 1 : 0);
    const f = gauss(p[0], 0.03, 0, 1) * (info.lip ? 1 : 0.5 * gauss(0, 1, p[1] - MOUTH_Y, 0.012));
    return [0, (up * 0.0019 - (1 - up) * 0.0011) * k * f, 0];
  },
  /** FF: the lower lip tucks under the upper teeth. */
  tuck(p, info, k) {
    if (!info.lip || (info.upper ?? 1) > 0.5) return [0, 0, 0];
    const f = gauss(p[0], 0.03, 0, 1) * (1 - (info.upper ?? 0));
    return [0, 0.0032 * k * f, -0.0042 * k * f];
  },
  tongueOut(p, info, k) {
    if (!info.tongue) return [0, 0, 0];
    const front = info.front ?? 0;
    return [0, 0.004 * k * front, 0.0105 * k * front];
  },
  tongueUp(p, info, k) {
    if (!info.tongue) return [0, 0, 0];
    const front = info.front ?? 0;
    return [0, 0.0065 * k * front, 0.0015 * k * front];
  },
  /** One mouth corner (`side` +1 left, -1 right) up and out, the cheek above it raised. */
  smile(p, info, side) {
    if (info.rigid) return [0, 0, 0];
    const corner = gauss(p[0] - side * MOUTH_W, 0.013, p[1] - MOUTH_Y, 0.012);
    const cheek = info.lip ? 0 : gauss(p[0] - side * 0.038, 0.017, p[1] - MOUTH_Y - 0.03, 0.016);
    return [side * 0.0028 * corner, 0.0036 * corner + 0.0022 * cheek, -0.0018 * corner + 0.0022 * cheek];
  },
  frown(p, info, side) {
    if (info.rigid) return [0, 0, 0];
    const corner = gauss(p[0] - side * MOUTH_W, 0.013, p[1] - MOUTH_Y, 0.012);
    return [side * 0.0008 * corner, -0.0032 * corner, -0.0006 * corner];
  },
};

/** The displacement of mouth target `name` at `p`. */
function mouthTarget(name, p, info) {
  /** @type {V3} */
  let d = [0, 0, 0];
  const addField = (field, amount) => {
    if (amount !== 0) d = add(d, FIELDS[field](p, info, amount));
  };
  if (name.startsWith("viseme_")) {
    const s = SHAPES[name.slice(7)];
    if (name === "viseme_sil") return d;
    addField("jaw", s.jaw);
    addField("wide", (s.mouthWidth - 1) / 0.2 - s.round * 0.4);
    addField("round", s.round);
    addField("press", s.lipPress);
    addField("part", Math.max(0, s.teeth - 0.5) * 2 * (1 - s.jaw) * (1 - s.lipPress));
    if (name === "viseme_FF") addField("tuck", 1);
    if (name === "viseme_TH") addField("tongueOut", s.tongue);
    else if (name === "viseme_DD" || name === "viseme_nn") addField("tongueUp", s.tongue);
    return d;
  }
  if (name === "jawOpen") addField("jaw", 1);
  if (name === "mouthSmileLeft") addField("smile", 1);
  if (name === "mouthSmileRight") addField("smile", -1);
  if (name === "mouthFrownLeft") addField("frown", 1);
  if (name === "mouthFrownRight") addField("frown", -1);
  return d;
}

// ---- parts ---------------------------------------------------------------------------------------------------

const outward = (center) => (p) => sub(p, center);
const towardViewer = () => /** @type {V3} */ ([0, 0, 1]);

/**
 * Grid cells at a level of detail: `n` at full detail (1), proportionally fewer below it, for the lighter model
 * that software WebGL draws (its frame cost follows the triangles). Counts stay even, so grids symmetric about
 * the midline stay so, and grids of four cells or fewer keep theirs.
 */
function cells(n, detail) {
  if (detail >= 1 || n <= 4) return n;
  return Math.max(4, 2 * Math.round((n * detail) / 2));
}

/** The skull as a grid before the eye sockets and the mouth are pressed in (for placing features on it). */
function skullPart(nu, nv) {
  const part = new Part("skull", outward(C));
  part.grid(nu, nv, (s, t) => ({ p: skull((s - 0.5) * 2 * Math.PI, t * Math.PI), c: SKIN }), true);
  return part;
}

function buildFace(base, eyes, zAt, detail) {
  const part = new Part("face", outward(C));
  // ~4 mm cells: finer grids cost software WebGL frames and change nothing visible (the lips, lids and
  // eyes are their own meshes; where they meet the skin, the depth test draws the seam per pixel).
  const nu = cells(96, detail);
  const nv = cells(72, detail);
  part.grid(nu, nv, (s, t) => {
    const u = (s - 0.5) * 2 * Math.PI;
    const v = t * Math.PI;
    let p = skull(u, v);
    const front = p[2] > C[2];
    let c = SKIN;
    if (front) {
      const x = p[0];
      const y = p[1];
      // Around each eye the skin drapes over the eyeball (a sphere a little inside the lids', blended smoothly into
      // the face, so no ring shows where they meet) and, inside the eye's opening plus a margin the lids cover,
      // sinks behind it: the grid's jagged edge there stays hidden under the lids.
      eyes.forEach((e, k) => {
        const hugR = EYE_R * 1.015;
        const dx = x - e[0];
        const dy = y - e[1];
        const rho = Math.hypot(dx, dy);
        if (rho < hugR * 1.6) {
          const g = lidGeometry(e, k === 0 ? 1 : -1);
          const l = Math.asin(clamp(dy / hugR, -1, 1));
          const h = Math.asin(clamp(dx / (hugR * Math.cos(l)), -1, 1));
          const m = 0.16;
          const inside = rho < hugR && Math.abs(h) < g.hc + m && l < g.upperEdge(h) + m && l > g.lowerEdge(h) - m;
          if (inside) p = [p[0], p[1], e[2] - 0.002];
          else {
            const hug = rho < hugR ? e[2] + Math.sqrt(hugR * hugR - rho * rho) : -Infinity;
            p = [p[0], p[1], smax(p[2], hug, 0.002)];
          }
        }
      });
      // The mouth: the skin inside the lips sinks deep behind them, so the open mouth shows its inside.
      const dy = y - MOUTH_Y;
      const e = Math.hypot(x / (MOUTH_W * 0.98), dy / (dy > 0 ? UPPER_LIP : LOWER_LIP));
      const sink = smoothstep(0.85, 0.45, e);
      p = [p[0], p[1], p[2] - 0.03 * sink];
      // Blush on the cheeks, a little shade under the brow ridge and around the jaw.
      const blush = gauss(Math.abs(x) - 0.043, 0.016, y - (MOUTH_Y + 0.034), 0.013);
      c = mix3(SKIN, BLUSH, 0.3 * blush);
    }
    const side = smoothstep(0.4, 1.3, Math.abs(u));
    c = mix3(c, SKIN_SHADE, 0.45 * side);
    return { p, c, info: { jaw: skinJawWeight(p), lipSkin: true } };
  }, true);
  // Ears: flattened ellipsoids half hidden by the hair.
  for (const side of [-1, 1]) {
    const centre = /** @type {V3} */ ([side * (A * 0.95), C[1] - 0.01, C[2] - 0.006]);
    const first = part.vertexCount;
    const ear = new Part("ear", outward(centre));
    ear.grid(cells(20, detail), cells(12, detail), (s, t) => {
      const u = s * 2 * Math.PI;
      const v = t * Math.PI;
      const n = [Math.sin(v) * Math.cos(u), Math.cos(v), Math.sin(v) * Math.sin(u)];
      const p = /** @type {V3} */ ([centre[0] + side * 0.0085 * (n[0] + 0.6), centre[1] + 0.02 * n[1], centre[2] + 0.011 * n[2]]);
      const inner = n[0] > 0.5 ? smoothstep(0.5, 0.95, n[0]) : 0;
      return { p, c: mix3(SKIN_SHADE, linear(0xc98b6b), 0.5 * inner) };
    }, true);
    for (let i = 0; i < ear.vertexCount; i++) part.vertex(ear.pos[i], ear.col[i], {});
    for (let k = 0; k < ear.idx.length; k += 3) part.idx.push(first + ear.idx[k], first + ear.idx[k + 1], first + ear.idx[k + 2]);
  }
  void base;
  void zAt;
  return part;
}

/** The lips (a ring from the meeting line to the outer contour, rolled inwards), the mouth's inside, teeth, tongue. */
function buildMouth(zAt, detail) {
  const nt = cells(72, detail);
  const zM = zAt(0, MOUTH_Y);
  /** The lips' rest position at angle `t` (0 = left corner, pi/2 = top) and `s` (-0.45 inside .. 1 outer edge). */
  const lipPoint = (t, s) => {
    const c = Math.cos(t);
    const sn = Math.sin(t);
    const upper = sn >= 0;
    const ax = Math.abs(c * MOUTH_W);
    // The upper lip's outline has a cupid's bow: two peaks beside a dip in the middle.
    const height = upper
      ? UPPER_LIP + 0.0013 * Math.exp(-(((ax - 0.0068) / 0.0042) ** 2)) - 0.0011 * Math.exp(-((ax / 0.0026) ** 2))
      : LOWER_LIP;
    const taper = 1 - 0.75 * Math.pow(c * c, 2);
    const inner = [MOUTH_W * 0.97 * c, MOUTH_Y + 0.0004 * sn];
    const outer = [MOUTH_W * c, MOUTH_Y + sn * height * (0.35 + 0.65 * taper)];
    const k = Math.max(0, s);
    const x = lerp(inner[0], outer[0], k);
    const y = lerp(inner[1], outer[1], k);
    const sigma = (s + 0.45) / 1.45;
    const bulge = 0.0048 * Math.pow(Math.sin(Math.PI * Math.min(1, sigma * 1.08)), 0.7) * taper * (upper ? 0.85 : 1);
    const recess = s < 0 ? 0.006 * (-s / 0.45) ** 1.2 : 0;
    // Inside the mouth the lips curl inwards (y towards the middle when open) and back.
    const z = zAt(x, y) + 0.0004 + bulge - recess - 0.0018 * k * k * k;
    const colour = s < 0.05 ? mix3(LIP_IN, LIP_LINE, 0.5 * Math.max(0, 1 - Math.abs(s) / 0.05)) : mix3(upper ? LIP_UP : LIP_LOW, LIP_IN, 0.3 * (1 - taper));
    // How much the point stays with the skull when the jaw opens: split gradually around the corners, so the
    // opening is an oval rather than a slot with square ends.
    const upperShare = 0.5 + 0.5 * Math.sign(sn) * Math.pow(Math.abs(sn), 0.6);
    return { p: /** @type {V3} */ ([x, y, z]), c: colour, upper: upperShare };
  };

  const lips = new Part("lips", towardViewer);
  const sSteps = [-0.45, -0.3, -0.15, 0, 0.08, 0.2, 0.35, 0.5, 0.65, 0.8, 0.92, 1];
  const ring = [];
  for (let j = 0; j < sSteps.length; j++) {
    const row = [];
    for (let i = 0; i < nt; i++) {
      const t = (i / nt) * 2 * Math.PI;
      const lp = lipPoint(t, sSteps[j]);
      row.push(lips.vertex(lp.p, lp.c, { lip: true, upper: lp.upper, jaw: 1 - lp.upper }));
    }
    row.push(row[0]);
    ring.push(row);
  }
  // The lips face outwards from the middle of the mouth and forwards; orient quads with that.
  lips.hint = (p) => [p[0] * 0.3, (p[1] - MOUTH_Y) * 0.3, 0.004];
  for (let j = 0; j + 1 < ring.length; j++) {
    for (let i = 0; i < nt; i++) lips.quad(ring[j][i], ring[j][i + 1], ring[j + 1][i + 1], ring[j + 1][i]);
  }

  // The inside: a bowl from the lips' innermost ring to a point deep in the mouth.
  const cavity = new Part("cavity", towardViewer);
  const bottom = /** @type {V3} */ ([0, MOUTH_Y - 0.003, zM - 0.022]);
  const rings = [1, 0.7, 0.4];
  const cid = [];
  for (const f of rings) {
    const row = [];
    for (let i = 0; i < nt; i++) {
      const t = (i / nt) * 2 * Math.PI;
      const lp = lipPoint(t, -0.45);
      const p = /** @type {V3} */ ([
        lerp(bottom[0], lp.p[0], f), lerp(bottom[1], lp.p[1], f), lerp(bottom[2], lp.p[2], f * f),
      ]);
      row.push(cavity.vertex(p, WHITE, { jaw: lerp(0.5, 1 - lp.upper, f), upper: lp.upper }));
    }
    row.push(row[0]);
    cid.push(row);
  }
  const centre = cavity.vertex(bottom, WHITE, { jaw: 0.5 });
  for (let j = 0; j + 1 < cid.length; j++) {
    for (let i = 0; i < nt; i++) cavity.quad(cid[j][i], cid[j][i + 1], cid[j + 1][i + 1], cid[j + 1][i]);
  }
  for (let i = 0; i < nt; i++) cavity.tri(cid[cid.length - 1][i], cid[cid.length - 1][i + 1], centre);

  // Teeth: two curved strips behind the lips, with a faint line between teeth; the lower row moves with the jaw.
  const teeth = new Part("teeth", towardViewer);
  for (const row of [{ top: MOUTH_Y + 0.0036, bottom: MOUTH_Y - 0.0013, jaw: 0, z: -0.0078 },
    { top: MOUTH_Y - 0.0018, bottom: MOUTH_Y - 0.006, jaw: 1, z: -0.0088 }]) {
    teeth.grid(cells(32, detail), 3, (s, t) => {
      const x = (s - 0.5) * 0.027;
      const tooth = Math.abs(Math.sin((x / 0.0042) * Math.PI));
      const shade = 0.86 + 0.14 * Math.pow(tooth, 0.3);
      const y = lerp(row.top, row.bottom, t) + (row.jaw ? 0.0004 : -0.0004) * (1 - tooth) * (t === 1 ? 1 : 0);
      const p = /** @type {V3} */ ([x, y, zM + row.z - 22 * x * x]);
      const c = mix3(linear(0xdcd6cf), linear(0xf6f3ef), shade * (row.jaw ? 0.9 : 1));
      // Not rigid for the width and rounding fields: the rows narrow with the lips so they never show outside them.
      return { p, c, info: { jaw: row.jaw } };
    });
  }

  // Tongue: a flattened ellipsoid on the floor of the mouth.
  const tc = /** @type {V3} */ ([0, MOUTH_Y - 0.0052, zM - 0.019]);
  const tongue = new Part("tongue", outward(tc));
  tongue.grid(cells(28, detail), cells(12, detail), (s, t) => {
    const u = s * 2 * Math.PI;
    const v = t * Math.PI;
    const n = [Math.sin(v) * Math.sin(u), Math.cos(v), Math.sin(v) * Math.cos(u)];
    const p = /** @type {V3} */ ([tc[0] + 0.011 * n[0], tc[1] + 0.0032 * n[1], tc[2] + 0.01 * n[2]]);
    return { p, c: WHITE, info: { tongue: true, jaw: 1, rigid: true, front: smoothstep(-0.5, 1, n[2]) } };
  }, true);
  return { lips, cavity, teeth, tongue };
}

/**
 * Upper and lower lids of the eye at `e` (side +1 left, -1 right) as shells around the eyeball, parametrised by
 * the horizontal angle h and the elevation lambda, so that a blink moves the lid edge's elevation.
 */
function lidGeometry(e, side) {
  const hc = 0.86; // the corners, in radians from the front
  const corner = (h) => (side * h > 0 ? 0.06 : -0.035); // outer corner a little higher than the inner one
  const open = (h) => Math.pow(Math.max(0, 1 - (h / hc) ** 2), 0.62);
  const upperEdge = (h) => corner(h) + (0.44 - corner(h)) * open(h);
  const lowerEdge = (h) => corner(h) + (-0.37 - corner(h)) * Math.pow(Math.max(0, 1 - (h / hc) ** 2), 0.8);
  const dir = (h, l, r) => /** @type {V3} */ ([
    e[0] + r * Math.sin(h) * Math.cos(l), e[1] + r * Math.sin(l), e[2] + r * Math.cos(h) * Math.cos(l),
  ]);
  return { hc, upperEdge, lowerEdge, dir };
}

const LID_TOP = 1.25;

/** The edges an eye's lids move to for each lid target (elevations per horizontal angle). */
function lidTargets(g) {
  return {
    blink: { up: (h) => lerp(g.lowerEdge(h), g.upperEdge(h), 0.1) - 0.01, low: (h) => lerp(g.lowerEdge(h), g.upperEdge(h), 0.1) },
    squint: { up: (h) => lerp(g.upperEdge(h), g.lowerEdge(h), 0.25), low: (h) => lerp(g.lowerEdge(h), g.upperEdge(h), 0.3) },
    wide: { up: (h) => g.upperEdge(h) + 0.16 * Math.max(0, 1 - (h / g.hc) ** 2), low: (h) => g.lowerEdge(h) - 0.05 },
  };
}

function buildLids(eyes, detail) {
  const lids = new Part("lids", towardViewer);
  const lashes = new Part("lashes", towardViewer);
  const catchlight = new Part("catchlight", towardViewer);
  const nh = cells(40, detail);
  const hmax = 1.3;
  eyes.forEach((e, k) => {
    const side = k === 0 ? 1 : -1;
    const g = lidGeometry(e, side);
    lids.hint = (p) => sub(p, e);
    // Upper lid: rows from the rim (inside the edge, closing the lid's thickness) up under the brow.
    // Dense enough that the chords between rows stay outside the skin draped under the lid.
    const rows = [-1, 0, 0.04, 0.1, 0.16, 0.24, 0.33, 0.43, 0.55, 0.7, 0.85, 1];
    const build = (upper) => {
      const ids = [];
      for (let j = 0; j < rows.length; j++) {
        const row = [];
        for (let i = 0; i <= nh; i++) {
          const h = (i / nh - 0.5) * 2 * hmax;
          const edge = upper ? g.upperEdge(h) : g.lowerEdge(h);
          const far = upper ? LID_TOP : -LID_TOP;
          const f = Math.max(0, rows[j]);
          const l = lerp(edge, far, f);
          // The lower lid hugs the eye more closely than the upper one, which folds over it.
          const r = rows[j] < 0 ? EYE_R * 1.01 : (upper ? LID_R : EYE_R * 1.06) * (1 + 0.05 * f);
          const p = g.dir(h, l, r);
          const nearEdge = rows[j] <= 0.04 && Math.abs(h) < g.hc * 1.05;
          let c = mix3(SKIN, SKIN_SHADE, upper ? 0.25 + 0.3 * smoothstep(0.3, 0, Math.abs(rows[j] - 0.2)) : 0.35);
          if (nearEdge) c = upper ? linear(0x2a1a22) : mix3(SKIN_SHADE, linear(0x8a4a48), 0.5);
          if (rows[j] < 0) c = linear(0xc98580);
          row.push(lids.vertex(p, c, { eye: k, upper, h, f: rows[j] }));
        }
        ids.push(row);
      }
      for (let j = 0; j + 1 < ids.length; j++) {
        for (let i = 0; i < nh; i++) lids.quad(ids[j][i], ids[j][i + 1], ids[j + 1][i + 1], ids[j + 1][i]);
      }
    };
    build(true);
    build(false);
    // Lashes: a dark fringe standing out of the upper lid's edge, longer towards the outer corner.
    lashes.hint = (p) => [0, 1, 0.3];
    const lid = [];
    for (let j = 0; j < 2; j++) {
      const row = [];
      for (let i = 0; i <= 24; i++) {
        const h = ((i / 24) * 2 - 1) * g.hc * 1.02;
        const outer = Math.max(0, side * h) / g.hc;
        const len = 0.0022 + 0.0022 * outer;
        const l = g.upperEdge(h) + (j ? 0.2 + 0.1 * outer : 0);
        const p = g.dir(h, l, LID_R + (j ? len : 0));
        row.push(lashes.vertex(p, WHITE, { eye: k, upper: true, h, f: 0, lash: j, lift: j ? 0.2 + 0.1 * outer : 0, len: j ? len : 0 }));
      }
      lid.push(row);
    }
    for (let i = 0; i < 24; i++) lashes.quad(lid[0][i], lid[0][i + 1], lid[1][i + 1], lid[1][i]);
    // Catchlight: a small bright spot on the cornea where the key light (upper left of the viewer) reflects.
    const spot = [-0.32, 0.3];
    const cc = g.dir(spot[0], spot[1], EYE_R * 1.012);
    const ring = [];
    for (let i = 0; i < 12; i++) {
      const a = (i / 12) * 2 * Math.PI;
      ring.push(catchlight.vertex(g.dir(spot[0] + 0.085 * Math.cos(a), spot[1] + 0.085 * Math.sin(a), EYE_R * 1.012), WHITE, {}));
    }
    const mid = catchlight.vertex(cc, WHITE, {});
    catchlight.hint = (p) => sub(p, e);
    for (let i = 0; i < 12; i++) catchlight.tri(ring[i], ring[(i + 1) % 12], mid);
  });
  return { lids, lashes, catchlight };
}

/** Where a lid vertex goes for lid target `target` of its eye. */
function lidDisplacement(p, info, eyes, target, eyeIndex) {
  if (info.eye !== eyeIndex || info.h === undefined) return /** @type {V3} */ ([0, 0, 0]);
  const e = eyes[eyeIndex];
  const g = lidGeometry(e, eyeIndex === 0 ? 1 : -1);
  const t = lidTargets(g)[target];
  const h = info.h;
  const f = Math.max(0, info.f);
  const far = info.upper ? LID_TOP : -LID_TOP;
  const edge0 = info.upper ? g.upperEdge(h) : g.lowerEdge(h);
  const edge1 = info.upper ? t.up(h) : t.low(h);
  const l0 = lerp(edge0, far, f) + (info.lift ?? 0);
  const l1 = lerp(edge1, far, f) + (info.lift ?? 0);
  const r = len3(sub(p, e));
  return sub(g.dir(h, l1, r), g.dir(h, l0, r));
}

const len3 = (v) => Math.hypot(v[0], v[1], v[2]);

function buildBrows(zAt) {
  const brows = new Part("brows", towardViewer);
  for (const side of [1, -1]) {
    brows.grid(18, 2, (s, t) => {
      const x = side * lerp(0.013, 0.057, s);
      const arch = 0.0052 * Math.sin(Math.PI * Math.pow(s, 0.75));
      const y0 = C[1] + 0.031 + arch - 0.003 * s * s;
      const thick = lerp(0.0052, 0.0014, Math.pow(s, 1.2));
      const y = y0 + (t - 0.5) * thick;
      const lift = Math.sin(Math.PI * t) * 0.0011;
      const p = /** @type {V3} */ ([x, y, zAt(x, y) + 0.0007 + lift]);
      return { p, c: WHITE, info: { side, s } };
    });
  }
  return brows;
}

function browDisplacement(p, info, name, zAt) {
  const { side, s } = info;
  let dx = 0;
  let dy = 0;
  if (name === "browInnerUp") dy = 0.0062 * Math.pow(1 - s, 1.4);
  else if (name === "browDownLeft" || name === "browDownRight") {
    if (side !== (name === "browDownLeft" ? 1 : -1)) return [0, 0, 0];
    dy = -0.0028 - 0.0022 * (1 - s);
    dx = -side * 0.0022 * (1 - s);
  } else {
    if (side !== (name === "browOuterUpLeft" ? 1 : -1)) return [0, 0, 0];
    dy = 0.0022 + 0.0052 * Math.pow(s, 1.1);
  }
  const x = p[0] + dx;
  const y = p[1] + dy;
  // Brows slide over the forehead: keep them on the skin.
  const dz = zAt(x, y) - zAt(p[0], p[1]);
  return /** @type {V3} */ ([dx, dy, dz]);
}

function buildEyeball(detail) {
  const sclera = new Part("sclera", (p) => p);
  sclera.grid(cells(36, detail), cells(24, detail), (s, t) => {
    const u = s * 2 * Math.PI;
    const v = t * Math.PI;
    // The pole points forward (+z), so the grid's rings are circles around the iris.
    const n = /** @type {V3} */ ([Math.sin(v) * Math.cos(u), Math.sin(v) * Math.sin(u), Math.cos(v)]);
    const c = mix3(linear(0xdfe3ea), WHITE, smoothstep(-0.2, 0.9, n[2]));
    return { p: scale(n, EYE_R), c };
  }, true);
  const iris = new Part("iris", (p) => p);
  const irisAngle = 0.5;
  iris.grid(cells(40, detail), cells(12, detail), (s, t) => {
    const u = s * 2 * Math.PI;
    const a = t * irisAngle;
    const n = /** @type {V3} */ ([Math.sin(a) * Math.cos(u), Math.sin(a) * Math.sin(u), Math.cos(a)]);
    const k = a / irisAngle;
    let c;
    if (k < 0.4) c = PUPIL;
    else if (k < 0.8) c = mix3(IRIS_IN, IRIS_OUT, (k - 0.4) / 0.4);
    else c = mix3(IRIS_OUT, IRIS_RING, (k - 0.8) / 0.2);
    // Fine radial streaks make the iris read as one at a glance.
    if (k >= 0.4) c = scale(c, 0.9 + 0.1 * Math.abs(Math.sin(u * 9)));
    // The iris sits a hair above the white, and dips slightly towards the pupil like a real one under its cornea.
    const r = EYE_R * (1.004 - 0.012 * (1 - k) * (1 - k));
    return { p: scale(n, r), c };
  }, true);
  return { sclera, iris };
}

function buildHair(detail) {
  const hair = new Part("hair", outward(C));
  const nu = cells(112, detail);
  const nv = cells(28, detail);
  // The hairline: a fringe of pointed locks over the forehead, sweeping from the avatar's left to its right;
  // above the ears at the sides; a bob down to the nape at the back.
  const vmax = (u) => {
    const au = Math.abs(u);
    // Front fringe, down the temples, then a bob that hangs to the chin at the sides and the nape at the back.
    let v = lerp(0.93, 1.5, smoothstep(0.3, 0.75, au));
    v = lerp(v, 2.95, smoothstep(0.75, 1.3, au));
    if (au < 1.15) {
      const phase = u / 0.23 + 0.35;
      const tri = 1 - Math.abs((phase - Math.floor(phase)) * 2 - 1);
      const sweep = 0.5 + 0.5 * Math.tanh(-u * 2.2); // longer locks on the avatar's right (viewer's left)
      v += (0.04 + 0.16 * Math.pow(tri, 2.2)) * smoothstep(1.15, 0.6, au) * (0.55 + 0.45 * sweep);
    }
    return v;
  };
  hair.grid(nu, nv, (s, t) => {
    const u = (s - 0.5) * 2 * Math.PI;
    const vm = vmax(u);
    const v = t * vm;
    const shell = (vv) => {
      const q = skull(u, Math.min(vv, 1.62));
      const n = sub(q, C);
      const nn = [n[0] / (A * A), n[1] / (B * B), n[2] / (D * D)];
      const l = Math.hypot(nn[0], nn[1], nn[2]);
      const volume = 0.005 + 0.0075 * smoothstep(0.2, 1.5, vv) * smoothstep(0.3, 1.8, Math.abs(u));
      // The edge thins out to lie on the skin, so the hairline reads as hair, not as a helmet's rim.
      const edge = 1 - 0.75 * smoothstep(0.82, 1, t) * smoothstep(1.9, 1.0, Math.abs(u));
      let p = add(q, scale(nn, (volume * edge + 0.0012) / l));
      if (vv > 1.62) {
        // Below the skull's widest line the bob hangs down instead of following the skull inwards.
        const k = vv - 1.62;
        p = [p[0] * (1 + 0.04 * k), p[1] - 0.068 * k, p[2] * (1 + 0.04 * k)];
      }
      return p;
    };
    const p = shell(v);
    // Shade: lighter at the crown, streaks along the strands.
    const streak = 0.88 + 0.12 * Math.sin(u * 29 + Math.sin(t * 3) * 1.5) ** 2;
    const c = scale(mix3(HAIR_MID, HAIR_BASE, smoothstep(0.1, 0.9, t)), streak);
    return { p, c };
  }, true);
  return hair;
}

function buildNeckAndBody(detail) {
  const neck = new Part("neck", (p) => [p[0], 0, p[2]]);
  neck.grid(cells(36, detail), cells(8, detail), (s, t) => {
    const a = s * 2 * Math.PI;
    const y = lerp(0.142, 0.0, t);
    const front = Math.max(0, Math.cos(a));
    const shade = smoothstep(0.1, 0.13, y) * front; // the chin's shadow
    const p = /** @type {V3} */ ([0.031 * Math.sin(a), y, -0.004 + 0.034 * Math.cos(a)]);
    return { p, c: mix3(SKIN_SHADE, linear(0xb77a5f), 0.5 * shade) };
  }, true);

  const top = 0.042;
  const W = (d) => 0.036 + 0.1 * (1 - Math.exp(-d / 0.03));
  const Dp = (d) => 0.036 + 0.058 * (1 - Math.exp(-d / 0.03));
  const section = (a, d) => {
    const c = Math.sin(a);
    const s = Math.cos(a);
    const x = W(d) * Math.sign(c) * Math.pow(Math.abs(c), 0.62);
    const z = -0.006 + Dp(d) * Math.sign(s) * Math.pow(Math.abs(s), 0.85);
    return /** @type {V3} */ ([x, top - d, z]);
  };
  const body = new Part("body", (p) => [p[0], 0.2, p[2] + 0.006]);
  body.grid(cells(64, detail), cells(18, detail), (s, t) => {
    const a = s * 2 * Math.PI;
    const d = 0.25 * Math.pow(t, 1.6);
    const p = section(a, d);
    return { p, c: mix3(CLOTH_LIGHT, CLOTH, smoothstep(0.02, 0.2, d)) };
  }, true);
  // The collar: a thin accent piping in a V below the neck, as on the 2D face.
  const zBody = (x, y) => frontZ(body, x, y, 0.05);
  const collar = new Part("collar", towardViewer);
  const path = [];
  for (let i = 0; i <= 24; i++) {
    const k = i / 24;
    const x = (k - 0.5) * 0.06;
    const y = top - 0.008 - 0.026 * (1 - (2 * k - 1) ** 2);
    path.push([x, y, zBody(x, y) + 0.0008]);
  }
  collar.grid(cells(24, detail), 4, (s, t) => {
    const q = path[Math.round(s * 24)];
    const a = t * Math.PI;
    const r = 0.0018;
    return { p: /** @type {V3} */ ([q[0], q[1] + r * Math.cos(a), q[2] + r * Math.sin(a)]), c: COLLAR };
  });
  return { neck, body, collar };
}

// ---- assembly ------------------------------------------------------------------------------------------------

function flat(list) {
  const out = new Float32Array(list.length * 3);
  list.forEach((v, i) => out.set(v, i * 3));
  return out;
}

/** A glTF primitive from `part`, with morph targets `names` computed by `displace(p, info, name)`. */
function primitive(part, material, names, displace, withNormals = true) {
  const n0 = normals(part);
  const targets = names.map((name) => {
    const moved = part.pos.map((p, i) => add(p, displace(p, part.info[i], name)));
    // Gaussian fields never reach zero: below 10 micrometres (and normals turned by less than 0.1 degree) a
    // vertex is left out of the target, which keeps the file small (sparse accessors) and the shader's work too.
    const cut = (v, eps) => /** @type {V3} */ (v.map((x) => (Math.abs(x) < eps ? 0 : x)));
    const delta = moved.map((p, i) => cut(sub(p, part.pos[i]), 1e-5));
    const t = { name, position: flat(delta) };
    if (withNormals) {
      const n1 = normals(part, moved);
      t.normal = flat(n1.map((n, i) => cut(sub(n, n0[i]), 2e-3)));
    }
    return t;
  });
  return {
    position: flat(part.pos),
    normal: flat(n0),
    color: flat(part.col),
    indices: Uint32Array.from(part.idx),
    material,
    targets,
  };
}

/**
 * The models the page loads (assets/), by file name, with the detail each is built at: the full model for WebGL
 * on a GPU, and the lite one for software WebGL (SwiftShader, llvmpipe), where a frame costs about 0.5 us of CPU
 * per triangle and half the grid resolution halves the frame's cost (bench_avatar).
 */
export const MODELS = [
  { file: "avatar.glb", detail: 1 },
  { file: "avatar-lite.glb", detail: 0.5 },
];

/**
 * Builds the whole avatar as a glTF document for `writeGlb`. `detail` scales the rendered grids (1: the full
 * model; the page's software-WebGL model, avatar-lite.glb, is 0.5); the skull that places the features stays fine
 * at every detail, so the face is laid out the same.
 */
export function buildAvatar({ detail = 1 } = {}) {
  const base = skullPart(136, 104); // fine, for placing features on the skull (not rendered)
  const zAt = (x, y) => frontZ(base, x, y, C[2] + D);
  const eyes = [1, -1].map((side) => {
    const x = side * EYE_X;
    const z = zAt(x, EYE_Y) - EYE_R + EYE_OUT;
    return /** @type {V3} */ ([x, EYE_Y, z]);
  });

  const face = buildFace(base, eyes, zAt, detail);
  const mouth = buildMouth(zAt, detail);
  const { lids, lashes, catchlight } = buildLids(eyes, detail);
  const brows = buildBrows(zAt);
  const { sclera, iris } = buildEyeball(detail);
  const hair = buildHair(detail);
  const { neck, body, collar } = buildNeckAndBody(detail);

  const mouthMorph = (p, info, name) => mouthTarget(name, p, info);
  const lidMorph = (p, info, name) => {
    const eyeIndex = name.endsWith("Left") ? 0 : 1;
    const target = name.startsWith("eyeBlink") ? "blink" : name.startsWith("eyeSquint") ? "squint" : "wide";
    return lidDisplacement(p, info, eyes, target, eyeIndex);
  };
  const none = () => /** @type {V3} */ ([0, 0, 0]);

  const meshes = [
    // The skin keeps its rest normals under the mouth targets: its moving part is small on screen and hidden by
    // the lips where it bends most, and the normal deltas would double the file.
    { name: "Face", primitives: [primitive(face, M.skin, MOUTH_TARGETS, mouthMorph, false)], targetNames: MOUTH_TARGETS },
    {
      name: "Mouth",
      primitives: [
        primitive(mouth.lips, M.lips, MOUTH_TARGETS, mouthMorph),
        primitive(mouth.cavity, M.mouth, MOUTH_TARGETS, mouthMorph),
        primitive(mouth.teeth, M.teeth, MOUTH_TARGETS, mouthMorph),
        primitive(mouth.tongue, M.tongue, MOUTH_TARGETS, mouthMorph),
      ],
      targetNames: MOUTH_TARGETS,
    },
    {
      name: "Lids",
      primitives: [
        primitive(lids, M.lids, LID_TARGETS, lidMorph),
        primitive(lashes, M.lashes, LID_TARGETS, lidMorph, false),
        primitive(catchlight, M.catchlight, LID_TARGETS, none, false),
      ],
      targetNames: LID_TARGETS,
    },
    {
      name: "Brows",
      primitives: [primitive(brows, M.brows, BROW_TARGETS, (p, info, name) => browDisplacement(p, info, name, zAt), false)],
      targetNames: BROW_TARGETS,
    },
    { name: "Eyeball", primitives: [primitive(sclera, M.sclera, [], none), primitive(iris, M.iris, [], none)], targetNames: [] },
    { name: "Hair", primitives: [primitive(hair, M.hair, [], none)], targetNames: [] },
    { name: "Neck", primitives: [primitive(neck, M.skin, [], none)], targetNames: [] },
    { name: "Body", primitives: [primitive(body, M.cloth, [], none), primitive(collar, M.cloth, [], none)], targetNames: [] },
  ];
  const mi = Object.fromEntries(meshes.map((m, i) => [m.name, i]));

  // Node order: 0 root; the root's children; the head's children. The page finds nodes by name.
  const nodes = [
    { name: "Avatar", children: [1, 2, 3] },
    { name: "Body", mesh: mi.Body },
    { name: "Neck", mesh: mi.Neck },
    { name: "Head", translation: HEAD_PIVOT, children: [4, 5, 6, 7, 8, 9, 10] },
    { name: "Face", mesh: mi.Face },
    { name: "Mouth", mesh: mi.Mouth },
    { name: "Lids", mesh: mi.Lids },
    { name: "Brows", mesh: mi.Brows },
    { name: "Hair", mesh: mi.Hair },
    { name: "EyeLeft", mesh: mi.Eyeball, translation: eyes[0] },
    { name: "EyeRight", mesh: mi.Eyeball, translation: eyes[1] },
  ];
  return {
    generator: "robot-agent scripts/avatar-gen",
    materials: MATERIALS,
    meshes,
    nodes,
    scene: [0],
    extras: {
      // For the page's camera: the point to frame (between the eyes, in the avatar's frame) and the head's height.
      eyeCentre: [0, HEAD_PIVOT[1] + EYE_Y, HEAD_PIVOT[2] + eyes[0][2]],
      headHeight: 2 * B,
      visemes: VISEME_NAMES,
    },
  };
}
