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

const EYE_R = 0.0176; // eyeball radius: stylised, large eyes like the 2D face's
const EYE_X = 0.0355;
const EYE_Y = C[1] + 0.003;
const EYE_OUT = 0.0038; // how far the eyeball's front stands out of the skin
const LID_R = EYE_R * 1.045; // the upper lid's edge, where the lashes grow
const MOUTH_Y = C[1] - 0.059;
const MOUTH_W = 0.0172; // half-width of the lips
const UPPER_LIP = 0.0047;
const LOWER_LIP = 0.0062;
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
const HAIR_BASE = linear(0x33242f); // a little cooler than the 2D face's, which the warm key light warms up
const HAIR_MID = linear(0x5c4458);
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
  { name: "hair", baseColor: [1, 1, 1], roughness: 0.62, doubleSided: true },
  { name: "cloth", baseColor: [1, 1, 1], roughness: 0.82 },
  { name: "brows", baseColor: linear(0x35212c), roughness: 0.7 },
  { name: "lashes", baseColor: linear(0x140c11), roughness: 0.95, doubleSided: true },
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
  // Nose: a narrow bridge from between the eyes that rises to a rounded tip, wings (alae) either side of the tip
  // and a short underside (columella) that turns back into the lip sharply, so it casts its own small shadow.
  const tipY = -0.034;
  const k = clamp((0.012 - y) / (0.012 - tipY), 0, 1);
  const under = y < tipY ? Math.exp(-(((y - tipY) / 0.0042) ** 2)) : 1;
  const bridge = y > 0.012 ? Math.exp(-(((y - 0.012) / 0.006) ** 2)) * 0.12 : 0.12 + 0.88 * Math.pow(k, 1.6);
  const sigma = lerp(0.0042, 0.0062, k);
  let z = 0.0108 * bridge * under * Math.exp(-((x / sigma) ** 2));
  z += 0.0032 * gauss(x, 0.0058, y - (tipY + 0.0005), 0.0052); // the ball of the tip
  z += 0.0046 * gauss(ax - 0.0098, 0.0036, y - (tipY - 0.0022), 0.0036); // wings
  z -= 0.0016 * gauss(ax - 0.0046, 0.0022, y - (tipY - 0.0062), 0.0018); // nostrils, under the tip
  z -= 0.0012 * gauss(ax - 0.0145, 0.0018, y - (tipY - 0.001), 0.0055); // the crease behind each wing
  // The philtrum: two soft ridges from the nose to the cupid's bow, a groove between them.
  z += 0.0007 * gauss(ax - 0.0042, 0.0017, y + 0.05, 0.006) - 0.0004 * gauss(x, 0.0022, y + 0.05, 0.006);
  z += 0.0032 * Math.exp(-(((y - 0.034) / 0.009) ** 2)) * smoothstep(0.066, 0.03, ax); // brow ridge
  z += 0.0042 * gauss(ax - 0.043, 0.015, y + 0.014, 0.014); // cheekbones
  z += 0.0045 * gauss(ax - 0.056, 0.009, y - 0.002, 0.016); // the outer rim of the eye sockets, round the eyeballs
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
  let x = A * nx * (1 - 0.26 * Math.pow(lower, 1.5)); // the jaw tapers to a small chin, as on the 2D face
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
    return [0, 0.0012 * k * f, -0.0032 * k * f];
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
    return [side * 0.0042 * corner, 0.0062 * corner + 0.0032 * cheek, -0.0026 * corner + 0.0028 * cheek];
  },
  frown(p, info, side) {
    if (info.rigid) return [0, 0, 0];
    const corner = gauss(p[0] - side * MOUTH_W, 0.013, p[1] - MOUTH_Y, 0.012);
    return [side * 0.0008 * corner, -0.0032 * corner, -0.0006 * corner];
  },
};

/**
 * The displacement of mouth target `name` at `p`. Skin under and around the lips (`info.lipBlend` > 0) moves
 * partly as the lips do, so that pressing, tucking or parting them never opens a gap beside them.
 */
function mouthTarget(name, p, info) {
  if (info.lipBlend) {
    const { lipBlend, ...rest } = info;
    const asSkin = lipTarget(name, p, rest);
    const asLip = lipTarget(name, p, { ...rest, lip: true });
    return add(scale(asSkin, 1 - lipBlend), scale(asLip, lipBlend));
  }
  return lipTarget(name, p, info);
}

function lipTarget(name, p, info) {
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
    if (name === "viseme_FF") {
      // The lower lip rolls in under the upper teeth, which show under the lifted upper lip.
      addField("tuck", 1);
      addField("part", 0.8);
    }
    if (name === "viseme_TH") addField("tongueOut", s.tongue);
    else if (name === "viseme_DD" || name === "viseme_nn") addField("tongueUp", s.tongue);
    return d;
  }
  if (name === "jawOpen") addField("jaw", 1);
  // A smile lifts the upper lip off the teeth a little (each side's target half of it, both together all).
  if (name === "mouthSmileLeft") {
    addField("smile", 1);
    addField("part", 0.35);
  }
  if (name === "mouthSmileRight") {
    addField("smile", -1);
    addField("part", 0.35);
  }
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

/**
 * The skin around the eyes: it drapes over the eyeball (a sphere just inside the lids', blended smoothly into the
 * face, so no ring shows where they meet) and, inside the eye's opening plus a margin the lids cover, sinks behind
 * it: the grid's jagged edge there stays hidden under the lids.
 */
function eyeHug(p, eyes, sink = true) {
  const [x, y] = p;
  let q = p;
  eyes.forEach((e, k) => {
    const hugR = EYE_R * 1.02;
    const dx = x - e[0];
    const dy = y - e[1];
    const rho = Math.hypot(dx, dy);
    if (rho >= hugR * 1.6) return;
    const g = lidGeometry(e, k === 0 ? 1 : -1);
    const l = Math.asin(clamp(dy / hugR, -1, 1));
    const h = Math.asin(clamp(dx / (hugR * Math.cos(l)), -1, 1));
    const m = 0.1;
    // Not beyond the corners: there the lids end, and the skin itself must cover the eyeball's side.
    const inside = rho < hugR && Math.abs(h) < g.hc + 0.02 && l < g.upperEdge(h) + m && l > g.lowerEdge(h) - m;
    // Sunk just inside the eyeball (behind the iris's bowl too), not deep behind it: the coarse triangles from
    // the hole's edge up to the skin then stay close to the eye, under the lids, even on the lite model.
    const sunkR = EYE_R * 0.9;
    if (inside && sink) q = [x, y, e[2] + Math.sqrt(Math.max(0, sunkR * sunkR - rho * rho))];
    else {
      const hug = rho < hugR ? e[2] + Math.sqrt(hugR * hugR - rho * rho) : -Infinity;
      q = [x, y, smax(q[2], hug, 0.005)];
    }
  });
  return /** @type {V3} */ (q);
}

/** The skin's colour at (x, y) on the front of the face (the lids take the same, so they blend into it). */
function skinColour(x, y) {
  // Blush on the cheeks.
  const blush = gauss(Math.abs(x) - 0.043, 0.016, y - (MOUTH_Y + 0.034), 0.013);
  let c = mix3(SKIN, BLUSH, 0.3 * blush);
  // Skin is not one colour: warmer on the nose's tip and wings, a touch lighter and cooler on the forehead
  // and the bridge, darker in the nostrils and the creases behind the nose's wings.
  const ry = y - C[1];
  const ax = Math.abs(x);
  c = mix3(c, BLUSH, 0.16 * gauss(x, 0.011, ry + 0.035, 0.007));
  c = mix3(c, linear(0xf8d9c2), 0.35 * smoothstep(0.02, 0.05, ry) + 0.25 * gauss(x, 0.004, ry + 0.012, 0.014));
  c = mix3(c, linear(0x7a3a36), 0.45 * gauss(ax - 0.0046, 0.0018, ry + 0.0402, 0.0014));
  c = mix3(c, SKIN_SHADE, 0.3 * gauss(ax - 0.0145, 0.002, ry + 0.035, 0.005));
  // The "white roll": skin a touch lighter just outside the lips' border, which makes the border crisp.
  if (ax < MOUTH_W) {
    const dy = y - MOUTH_Y;
    const e = Math.abs(dy) / Math.max(1e-4, lipOutline(x, dy > 0));
    c = mix3(c, linear(0xfbe0cf), 0.5 * Math.exp(-(((e - 1.18) / 0.14) ** 2)) * smoothstep(MOUTH_W, MOUTH_W * 0.6, ax));
  }
  return c;
}

function buildFace(base, eyes, zAt, detail) {
  const part = new Part("face", outward(C));
  // ~4 mm cells: finer grids cost software WebGL frames and change nothing visible (the lips, lids and
  // eyes are their own meshes; where they meet the skin, the depth test draws the seam per pixel).
  const nu = cells(96, detail);
  const nv = cells(72, detail);
  part.grid(nu, nv, (s, t) => {
    // Cells are about 2.5 times as dense over the face as over the back of the head, which the hair hides:
    // the nose, lips and lids need the detail, and the triangles cost software WebGL frame time.
    const xs = 2 * s - 1;
    const u = Math.PI * (0.42 * xs + 0.58 * xs * xs * xs);
    const v = Math.PI * (t - (0.5 / (2 * Math.PI)) * (Math.sin(2 * Math.PI * (t - 0.6)) - Math.sin(-2 * Math.PI * 0.6)));
    let p = skull(u, v);
    let np = p;
    let lipInfo = {};
    const front = p[2] > C[2];
    let c = SKIN;
    if (front) {
      const x = p[0];
      const y = p[1];
      np = eyeHug(p, eyes, false);
      p = eyeHug(p, eyes);
      // The mouth: the skin inside the lips sinks deep behind them, so the open mouth shows its inside.
      // Only inside the lips' own outline (which tapers towards the corners), so no hole shows beside them.
      const dy = y - MOUTH_Y;
      const outline = Math.max(1e-4, lipOutline(x, dy > 0));
      const e = Math.abs(dy) / outline;
      const within = smoothstep(1.0, 0.92, Math.abs(x) / MOUTH_W);
      const sink = smoothstep(0.75, 0.4, e) * within;
      // Under the lips' border the skin dips a little, so the lips' edge, not a ragged crossing, is the border.
      const under = smoothstep(1.12, 0.95, e) * within;
      p = [p[0], p[1], p[2] - 0.03 * sink - 0.0007 * under];
      // The skin under the lips moves with them (pressed, tucked, parted), so their moves never open a gap.
      const follow = smoothstep(1.5, 0.95, e) * within;
      if (follow > 0) lipInfo = { lipBlend: follow, upper: dy > 0 ? 1 : 0 };
      // Skin sunk out of sight is the mouth's inside if it ever shows: dark, not skin-coloured.
      c = mix3(skinColour(x, y), linear(0x3a0e18), smoothstep(0.05, 0.4, sink));
    }
    const side = smoothstep(0.4, 1.3, Math.abs(u));
    c = mix3(c, SKIN_SHADE, 0.45 * side);
    return { p, c, np, info: { jaw: skinJawWeight(p), lipSkin: true, ...lipInfo } };
  }, true);
  // Ears: a curved plate with a rolled rim (helix), a bowl (concha) and a lobe, standing out from the head
  // towards the back; the hair is tucked behind them.
  for (const side of [-1, 1]) {
    const centre = /** @type {V3} */ ([side * 0.075, C[1] - 0.013, C[2] - 0.014]);
    const first = part.vertexCount;
    const ear = new Part("ear", (p) => [side, 0, 0]);
    const rings = [0, 0.22, 0.42, 0.58, 0.7, 0.8, 0.88, 0.95, 1];
    ear.grid(cells(24, detail), rings.length - 1, (s, t, i, j) => {
      const th = s * 2 * Math.PI; // 0: towards the back, pi/2: up
      const rho = rings[j];
      const up = Math.sin(th);
      const back = Math.cos(th);
      // Taller than wide, the lobe narrower than the top; the front edge joins the head.
      const hw = 0.0135 * (up < 0 ? 1 - 0.25 * up * up : 1);
      const hh = up > 0 ? 0.025 : 0.021;
      const xl = rho * hw * back;
      const yl = rho * hh * up;
      const helix = 0.0026 * Math.exp(-(((rho - 0.88) / 0.09) ** 2)) * (up < -0.6 ? 0.4 : 1);
      const concha = -0.0022 * smoothstep(0.62, 0.15, rho) * smoothstep(-0.9, -0.2, up + 0.2 * back);
      const lobe = 0.0012 * smoothstep(-0.4, -0.9, up) * smoothstep(0.9, 0.4, rho);
      const standOut = 0.012 * smoothstep(-1, 1, xl / hw) * rho + 0.0015 * rho;
      const out = helix + concha + lobe + standOut;
      const p = /** @type {V3} */ ([centre[0] + side * out, centre[1] + yl, centre[2] - xl]);
      let c = mix3(mix3(SKIN, SKIN_SHADE, 0.45), BLUSH, 0.18);
      c = mix3(c, linear(0xb06a5a), 0.45 * smoothstep(0.6, 0.1, rho) + 0.25 * Math.exp(-(((rho - 0.78) / 0.05) ** 2)));
      return { p, c };
    }, true);
    for (let i = 0; i < ear.vertexCount; i++) part.vertex(ear.pos[i], ear.col[i], {});
    for (let k = 0; k < ear.idx.length; k += 3) part.idx.push(first + ear.idx[k], first + ear.idx[k + 1], first + ear.idx[k + 2]);
  }
  void base;
  void zAt;
  return part;
}

/** The lips' outer contour above (`upper`) or below the mouth line at x: the height of the vermilion there. */
function lipOutline(x, upper) {
  const c = clamp(x / MOUTH_W, -1, 1);
  const sn = Math.sqrt(1 - c * c);
  const ax = Math.abs(x);
  // The upper lip's outline has a cupid's bow: two peaks beside a dip in the middle.
  const height = upper
    ? UPPER_LIP + 0.0013 * Math.exp(-(((ax - 0.0068) / 0.0042) ** 2)) - 0.0011 * Math.exp(-((ax / 0.0026) ** 2))
    : LOWER_LIP;
  const taper = 1 - 0.75 * Math.pow(c * c, 2);
  return sn * height * (0.35 + 0.65 * taper);
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
    const bulge = 0.0036 * Math.pow(Math.sin(Math.PI * Math.min(1, sigma * 1.08)), 0.7) * taper * (upper ? 0.85 : 1);
    const recess = s < 0 ? 0.006 * (-s / 0.45) ** 1.2 : 0;
    // Inside the mouth the lips curl inwards (y towards the middle when open) and back.
    const z = zAt(x, y) + 0.0004 + bulge - recess - 0.0008 * k * k * k;
    let colour = s < 0.05 ? mix3(mix3(LIP_IN, linear(0x5a1e2e), smoothstep(-0.1, -0.4, s)), LIP_LINE, 0.5 * Math.max(0, 1 - Math.abs(s) / 0.05)) : mix3(upper ? LIP_UP : LIP_LOW, LIP_IN, 0.3 * (1 - taper));
    // The vermilion's border: a slightly deeper line at its edge; a soft highlight on the lower lip's fullness.
    if (s > 0.85) colour = mix3(colour, LIP_LINE, 0.35 * smoothstep(0.85, 1, s));
    if (!upper && s > 0.1) colour = mix3(colour, linear(0xeea0aa), 0.45 * Math.exp(-(((s - 0.45) / 0.2) ** 2)) * Math.exp(-((c / 0.45) ** 2)));
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
  for (const row of [{ top: MOUTH_Y + 0.003, bottom: MOUTH_Y - 0.0024, jaw: 0, z: -0.0062 },
    { top: MOUTH_Y - 0.0022, bottom: MOUTH_Y - 0.005, jaw: 1, z: -0.0082 }]) {
    teeth.grid(cells(32, detail), 3, (s, t) => {
      const x = (s - 0.5) * 0.022;
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
  // High enough, and lowered by the jaw by less than the lower lip is, that an open mouth shows it over the lower
  // lip; its tip stays behind the lower teeth.
  const tc = /** @type {V3} */ ([0, MOUTH_Y - 0.0036, zM - 0.0185]);
  const tongue = new Part("tongue", outward(tc));
  tongue.grid(cells(28, detail), cells(12, detail), (s, t) => {
    const u = s * 2 * Math.PI;
    const v = t * Math.PI;
    const n = [Math.sin(v) * Math.sin(u), Math.cos(v), Math.sin(v) * Math.cos(u)];
    const p = /** @type {V3} */ ([tc[0] + 0.0105 * n[0], tc[1] + 0.0036 * n[1], tc[2] + 0.0095 * n[2]]);
    return { p, c: WHITE, info: { tongue: true, jaw: 0.86, rigid: true, front: smoothstep(-0.5, 1, n[2]) } };
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
  const upperEdge = (h) => corner(h) + (0.52 - corner(h)) * open(h);
  const lowerEdge = (h) => corner(h) + (-0.41 - corner(h)) * Math.pow(Math.max(0, 1 - (h / hc) ** 2), 0.8);
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

function buildLids(eyes, skinZ, detail) {
  const lids = new Part("lids", towardViewer);
  const lashes = new Part("lashes", towardViewer);
  const catchlight = new Part("catchlight", towardViewer);
  const nh = cells(40, detail);
  const hmax = 1.02;
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
          // Towards the nose the lids stop just past the corner: the skin falls away there, and a longer lid
          // would stand out of it, seen from the side.
          const hi = (i / nh - 0.5) * 2 * hmax;
          const hEnd = side * hi < 0 ? g.hc * 1.06 : hmax;
          const h = clamp(hi, -hEnd, hEnd);
          const edge = upper ? g.upperEdge(h) : g.lowerEdge(h);
          const far = upper ? LID_TOP : -LID_TOP;
          const f = Math.max(0, rows[j]);
          const l = lerp(edge, far, f);
          // The lower lid hugs the eye closely and tucks under the cheek's skin within a few millimetres; the
          // upper one folds over the eye and tucks under the skin below the brow at its crease, so neither stands
          // out of the face as a shell (the skin around is the same colour, so the lids blend into it).
          const f0 = rows[j];
          let r;
          if (f0 < 0) r = EYE_R * 1.01;
          else if (upper) r = LID_R * (1 + 0.033 * Math.sin(Math.PI * Math.min(1, f / 0.5)));
          else r = EYE_R * 1.035;
          let p = g.dir(h, l, r);
          // Away from the edge each lid merges into the skin, just under it: the lower lid within a few
          // millimetres, the upper one above its crease. So the lids never stand out of the face as shells, and
          // the skin (of the same colour) takes over without a seam.
          // Beyond the corners both lids merge into the skin too, so their ends never show as a step.
          const beyond = smoothstep(g.hc * 1.02, side * h < 0 ? g.hc * 1.06 : hmax, Math.abs(h));
          const w = Math.max(upper ? smoothstep(0.4, 0.8, f) : smoothstep(0.12, 0.5, f), beyond);
          if (w > 0) {
            p = /** @type {V3} */ ([p[0], p[1], lerp(p[2], skinZ(p[0], p[1]) - 0.0003, w)]);
            // Never into the eyeball, which would show through.
            const d = sub(p, e);
            const dl = len3(d);
            if (dl < EYE_R * 1.012) p = add(e, scale(d, (EYE_R * 1.012) / dl));
          }
          const inside = Math.abs(h) < g.hc * 1.05;
          let c = skinColour(p[0], p[1]);
          if (upper) {
            // A soft shade in the crease and along the lid's edge, a thin dark lash line on the rim itself.
            c = mix3(c, SKIN_SHADE, 0.5 * gauss(f - 0.42, 0.1, 0, 1) + 0.35 * smoothstep(0.12, 0, f));
            if (f0 < 0 && inside) c = linear(0x2a1a22);
            else if (f0 === 0 && inside) c = mix3(c, linear(0x2a1a22), 0.6);
          } else {
            c = mix3(c, mix3(SKIN_SHADE, BLUSH, 0.25), 0.4 * smoothstep(0.2, 0, f));
            if (f0 < 0) c = linear(0xc98580);
          }
          row.push(lids.vertex(p, c, { eye: k, upper, h, f: rows[j], merged: w }));
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
        // Short in the middle, a flick towards the outer corner, as the 2D face draws them.
        const len = 0.0009 + 0.0034 * outer * outer;
        const l = g.upperEdge(h) + (j ? 0.1 + 0.22 * outer : 0);
        const p = g.dir(h, l, LID_R + (j ? len : 0));
        row.push(lashes.vertex(p, WHITE, { eye: k, upper: true, h, f: 0, lash: j, lift: j ? 0.1 + 0.22 * outer : 0, len: j ? len : 0 }));
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
  // The parts of the lids merged into the skin (beyond the corners, under the brow and the cheek) stay put, or
  // they would fold out of it or uncover the skin's opening; the lid stretches between them and its edge.
  return scale(sub(g.dir(h, l1, r), g.dir(h, l0, r)), 1 - (info.merged ?? 0));
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
  // The white leaves the front cap open where the iris sits (else it would cover the iris's dip); the iris is a
  // shallow bowl behind where the cornea would be, so it keeps its depth as the eye turns, with a dark limbal
  // ring that reads as its edge.
  const irisAngle = 0.56;
  const sclera = new Part("sclera", (p) => p);
  sclera.grid(cells(36, detail), cells(14, detail), (s, t) => {
    const u = s * 2 * Math.PI;
    const v = irisAngle + t * (1.95 - irisAngle); // the back half never shows, even with the eye turned
    // The pole points forward (+z), so the grid's rings are circles around the iris.
    const n = /** @type {V3} */ ([Math.sin(v) * Math.cos(u), Math.sin(v) * Math.sin(u), Math.cos(v)]);
    // Whiter in front, greyer and a touch warm towards the corners where the lids shade it.
    const c = mix3(linear(0xcfc6c8), linear(0xf4f1ee), smoothstep(0.1, 0.85, n[2]));
    return { p: scale(n, EYE_R), c };
  }, true);
  const iris = new Part("iris", (p) => p);
  iris.grid(cells(40, detail), cells(14, detail), (s, t) => {
    const u = s * 2 * Math.PI;
    const a = t * irisAngle;
    const n = /** @type {V3} */ ([Math.sin(a) * Math.cos(u), Math.sin(a) * Math.sin(u), Math.cos(a)]);
    const k = a / irisAngle;
    let c;
    if (k < 0.36) c = PUPIL;
    else if (k < 0.44) c = mix3(PUPIL, IRIS_IN, (k - 0.36) / 0.08);
    else if (k < 0.82) c = mix3(IRIS_IN, IRIS_OUT, (k - 0.44) / 0.38);
    else c = mix3(IRIS_OUT, IRIS_RING, smoothstep(0.82, 0.97, k));
    // Radial fibres and a lighter upper half (lit through the cornea) make it read as an iris at a glance.
    if (k >= 0.4 && k < 0.95) c = scale(c, 0.82 + 0.18 * Math.abs(Math.sin(u * 11 + 3 * k)) + 0.12 * Math.max(0, n[1] / Math.sin(a + 1e-6)) * (1 - k));
    // A bowl: the pupil sits about 0.9 mm behind the limbus.
    const r = EYE_R * (1 - 0.055 * (1 - k * k));
    return { p: scale(n, r), c };
  }, true);
  return { sclera, iris };
}

/** Where the hair ends (polar angle from the crown) at azimuth `u`: fringe, temples, tucked behind the ears, bob. */
function hairEnd(u) {
  const au = Math.abs(u);
  // The fringe sweeps from the avatar's right (viewer's left, shorter) across to its left in one smooth curve,
  // in a few rounded locks, as the 2D face draws it.
  const sweep = 0.5 + 0.5 * Math.tanh(u * 2.4);
  const lockPhase = (u + 0.62) / 0.42;
  const scallop = 0.03 * Math.pow(Math.sin(Math.PI * (lockPhase - Math.floor(lockPhase))), 1.5);
  const fringe = 1.03 + 0.12 * sweep + scallop * smoothstep(0.9, 0.5, au);
  // Down the temples to just above the ears (tucked behind them), then the bob: to the jaw at the sides, the
  // nape behind.
  let v = lerp(Math.min(fringe, 1.16), 1.5, smoothstep(0.62, 1.05, au));
  v = lerp(fringe, v, smoothstep(0.3, 0.62, au));
  v += 0.16 * Math.exp(-(((au - 1.3) / 0.13) ** 2)); // a short sideburn in front of the ear
  v = lerp(v, 3.2, smoothstep(1.8, 2.1, au));
  // The bob ends in rounded locks, a little longer at the front of each side.
  if (au > 1.8) {
    const ph = (u * 7) / Math.PI;
    v += 0.05 * Math.pow(Math.sin(Math.PI * (ph - Math.floor(ph))), 0.6) - 0.05 * smoothstep(2.3, 3.1, au);
  }
  return v;
}

/**
 * A point of the hair's shell at azimuth `u`, at fraction `t` of the way from the crown to the hair's end there,
 * with its colour: the shell rises and falls across the strands' direction in rounded locks with darker grooves.
 * `extra` lifts the point further off the head (for the lock cards lying on the shell).
 */
function hairPoint(u, t, extra = 0) {
  const LOCKS = 19;
  const vm = hairEnd(u);
  const v = t * vm;
  const au = Math.abs(u);
  const q = skull(u, Math.min(v, 1.62));
  const n = sub(q, C);
  const nn = [n[0] / (A * A), n[1] / (B * B), n[2] / (D * D)];
  const l = Math.hypot(nn[0], nn[1], nn[2]);
  // The strands run from the crown down, and sweep sideways across the fringe.
  const twist = -1.2 * smoothstep(1.2, 0.2, au) * smoothstep(0.15, 0.9, t) * v;
  // Locks of uneven widths: the phase runs a little faster and slower round the head.
  const uu = u + twist + 0.06 * Math.sin(u * 5 + 1.3) + 0.03 * Math.sin(u * 11 + 0.4);
  const phase = (uu * LOCKS) / (2 * Math.PI);
  const ridge = Math.pow(Math.sin(Math.PI * (phase - Math.floor(phase))), 0.7); // 0 in a groove, 1 on a crest
  const locks = smoothstep(0.05, 0.3, t); // the crown is smooth where the strands start
  const volume = 0.008 + 0.013 * smoothstep(0.2, 1.4, v) * smoothstep(0.3, 1.6, au);
  // The edge thins out to lie on the skin at the hairline, but keeps a rounded thickness where the bob ends.
  const hairline = smoothstep(1.9, 1.2, au);
  const edge = 1 - 0.88 * smoothstep(0.75, 1, t) * hairline;
  const lift = (volume + 0.0022 * ridge * locks) * edge + 0.0012 + extra;
  let p = add(q, scale(nn, lift / l));
  if (v > 1.62) {
    // Below the skull's widest line the bob hangs down instead of following the skull inwards, curling in a
    // little at its ends.
    const k = v - 1.62;
    const curl = 1 + 0.05 * k - 0.06 * smoothstep(0.75, 1, t) * (1 - hairline);
    p = [p[0] * (curl + 0.06 * k), p[1] - 0.066 * k, p[2] * curl];
  }
  // Shade: darker in the grooves and underneath, lighter on the crests; a soft band of sheen across the
  // crown, as the 2D face's highlight.
  let c = mix3(HAIR_MID, HAIR_BASE, smoothstep(0.2, 0.95, t));
  c = scale(c, 0.72 + 0.28 * lerp(1, ridge, locks));
  const sheen = Math.exp(-(((v - 0.55 - 0.1 * Math.cos(u)) / 0.14) ** 2)) * smoothstep(2.4, 1.2, au) * (0.4 + 0.6 * ridge);
  c = mix3(c, linear(0x7a6070), 0.4 * sheen);
  return { p: /** @type {V3} */ (p), c };
}

/**
 * Lock cards: ribbons lying just off the shell, each along a path from its root to a pointed (fringe) or rounded
 * (bob) tip a little past the shell's edge, so that the hair reads as locks laid over each other and the fringe's
 * edge is made of their tips. `path(t)` gives [u, t] on the shell; `width(t)` the half-width in radians of u.
 */
function lockCard(part, path, width, lift, steps) {
  const rows = [];
  for (let j = 0; j <= steps; j++) {
    const k = j / steps;
    const [u, t] = path(k);
    const w = width(k);
    const off = lift * (0.6 + 0.4 * Math.sin(Math.PI * k));
    const row = [-1, 0, 1].map((side) => {
      const hp = hairPoint(u + side * w, t, off * (1 - 0.35 * Math.abs(side)));
      // The card's middle catches a little more light than its sides, its tip is darker.
      const c = scale(hp.c, (1.08 - 0.12 * Math.abs(side)) * (1 - 0.25 * smoothstep(0.7, 1, k)));
      return part.vertex(hp.p, c, {});
    });
    rows.push(row);
  }
  for (let j = 0; j < steps; j++) {
    part.quad(rows[j][0], rows[j][1], rows[j + 1][1], rows[j + 1][0]);
    part.quad(rows[j][1], rows[j][2], rows[j + 1][2], rows[j + 1][1]);
  }
}

function buildHair(detail) {
  const hair = new Part("hair", outward(C));
  hair.grid(cells(128, detail), cells(30, detail), (s, t) => hairPoint((s - 0.5) * 2 * Math.PI, t), true);
  const steps = cells(14, detail);
  // The fringe: locks from the parting on the avatar's right sweeping across the forehead to its left, their
  // pointed tips just past the shell's edge.
  const fringe = [[-0.58, 0.4, 1.0], [-0.3, 0.42, 1.035], [0.0, 0.44, 1.02], [0.3, 0.42, 1.045], [0.6, 0.36, 1.025]];
  fringe.forEach(([tipU, w0, reach], i) => {
    const rootU = -0.95 + 0.2 * i;
    lockCard(hair, (k) => [lerp(rootU, tipU, smoothstep(0, 1, k)), lerp(0.08, reach, k)],
      (k) => w0 * 0.5 * (1 - Math.pow(k, 2.6)) + 0.012, 0.0018, steps);
  });
  // Side locks over the bob, ending in rounded tips.
  for (const side of [-1, 1]) {
    for (const [u0, w0] of [[1.95, 0.2], [2.3, 0.22], [2.65, 0.2]]) {
      lockCard(hair, (k) => [side * (u0 - 0.08 * k), lerp(0.3, 1.015, k)],
        (k) => w0 * 0.5 * (1 - 0.6 * Math.pow(k, 4)), 0.0014, steps);
    }
  }
  return hair;
}

/** The neck's half-width and half-depth at height `y`: it flares at its base into the slope of the shoulders. */
function neckRadii(y) {
  const base = smoothstep(0.08, -0.01, y);
  return [0.024 + 0.054 * base * base, 0.029 + 0.015 * base];
}
const NECK_Z = -0.004;

/** The shirt's neckline: its height at angle `a` around the neck (0 = front): a soft scoop in front. */
const necklineY = (a) => 0.042 - 0.02 * Math.max(0, Math.cos(a)) ** 2;

function buildNeckAndBody(detail) {
  const neck = new Part("neck", (p) => [p[0], 0, p[2] - NECK_Z]);
  neck.grid(cells(36, detail), cells(12, detail), (s, t) => {
    const a = s * 2 * Math.PI;
    const y = lerp(0.142, -0.005, t);
    const [rx, rz] = neckRadii(y);
    const front = Math.max(0, Math.cos(a));
    // The chin's shadow on the front of the neck, and the neck a little darker than the face overall.
    const shade = smoothstep(0.085, 0.125, y) * front;
    const p = /** @type {V3} */ ([rx * Math.sin(a), y, NECK_Z + rz * Math.cos(a)]);
    const c = mix3(mix3(SKIN, SKIN_SHADE, 0.4), linear(0xb77a5f), 0.55 * shade);
    return { p, c };
  }, true);

  // The shirt: from the neckline out over the slope of the shoulders (trapezius), round the shoulder and down.
  const CHEST = [0.148, 0.085];
  const ROUND = 0.034; // the shoulders' roundness
  const section = (a, rx, rz) => {
    const sn = Math.sin(a);
    const cs = Math.cos(a);
    // A superellipse: squarer than an ellipse, so the shoulders are broad and the chest flat.
    return [rx * Math.sign(sn) * Math.pow(Math.abs(sn), 0.7), NECK_Z + rz * Math.sign(cs) * Math.pow(Math.abs(cs), 0.8)];
  };
  const TOP = 8;
  const ROUNDS = 5;
  const DOWN = 6;
  const rowsOf = TOP + ROUNDS + DOWN;
  const body = new Part("body", (p) => [p[0], 0.25, p[2] - NECK_Z]);
  body.grid(cells(64, detail), cells(rowsOf, detail), (s, t) => {
    const a = s * 2 * Math.PI;
    const yN = necklineY(a);
    const [nx, nz] = neckRadii(yN);
    const r = t * rowsOf;
    let rx;
    let rz;
    let y;
    // Where the slope meets the shoulder's roundness: level all round (the neckline's scoop is only the opening),
    // a little lower at the shoulders' tips.
    const yS = 0.006 - 0.012 * Math.abs(Math.sin(a));
    if (r <= TOP) {
      const w = r / TOP;
      rx = lerp(nx + 0.001, CHEST[0] - ROUND, Math.pow(w, 0.9));
      rz = lerp(nz + 0.001, CHEST[1] - ROUND * 0.6, w);
      y = yN + (yS - yN) * Math.pow(w, 1.4);
    } else if (r <= TOP + ROUNDS) {
      const phi = ((r - TOP) / ROUNDS) * (Math.PI / 2);
      rx = CHEST[0] - ROUND * (1 - Math.sin(phi));
      rz = CHEST[1] - ROUND * 0.6 * (1 - Math.sin(phi));
      y = yS - ROUND * (1 - Math.cos(phi));
    } else {
      const w = (r - TOP - ROUNDS) / DOWN;
      rx = CHEST[0] * (1 - 0.04 * w);
      rz = CHEST[1];
      y = yS - ROUND - 0.22 * w;
    }
    const [x, z] = section(a, rx, rz);
    const c = mix3(CLOTH_LIGHT, CLOTH, smoothstep(0.01, -0.12, y));
    return { p: /** @type {V3} */ ([x, y, z]), c };
  }, true);

  // The collar: a thin accent piping along the neckline's front, as on the 2D face.
  const collar = new Part("collar", towardViewer);
  const n = cells(24, detail);
  collar.grid(n, 4, (s, t) => {
    const a = (s - 0.5) * 2.2;
    const yN = necklineY(a);
    const [nx, nz] = neckRadii(yN);
    const [x, z] = section(a, nx + 0.0025, nz + 0.0025);
    const b = t * Math.PI;
    const r = 0.0017;
    return { p: /** @type {V3} */ ([x, yN - 0.001 + r * Math.cos(b), z + r * Math.sin(b)]), c: COLLAR };
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
  const skinZ = (x, y) => eyeHug([x, y, zAt(x, y)], eyes, false)[2];
  const { lids, lashes, catchlight } = buildLids(eyes, skinZ, detail);
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
