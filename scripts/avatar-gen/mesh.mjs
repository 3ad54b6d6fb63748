//! Geometry helpers for the avatar generator: indexed parts built from parameter grids, normals, morph deltas.
// @ts-check
//
// A part is a list of vertices (base position, colour and free per-vertex `info` the deformation fields read)
// and triangles. Triangles are oriented by a hint (the direction the front face must look), so builders never
// have to get the winding of each grid right by hand.

/** @typedef {[number, number, number]} V3 */

export class Part {
  /** `hint(p)` gives the outward direction at a triangle's centroid. */
  constructor(name, hint) {
    this.name = name;
    this.hint = hint;
    /** @type {V3[]} */
    this.pos = [];
    /** @type {V3[]} */
    this.col = [];
    /**
     * Where each vertex is for shading (its normal): usually where it is, but skin pushed out of sight (behind
     * the lids, inside the lips) keeps the normal of the surface it was pushed from, so that the visible skin
     * next to it does not shade as if it bent into a hole.
     * @type {V3[]}
     */
    this.npos = [];
    /** @type {object[]} */
    this.info = [];
    /** @type {number[]} */
    this.idx = [];
  }

  vertex(p, c, info = {}, np = p) {
    this.pos.push(p);
    this.npos.push(np);
    this.col.push(c);
    this.info.push(info);
    return this.pos.length - 1;
  }

  tri(a, b, c) {
    if (a === b || b === c || a === c) return;
    const pa = this.pos[a];
    const n = cross(sub(this.pos[b], pa), sub(this.pos[c], pa));
    const centroid = scale(add(add(pa, this.pos[b]), this.pos[c]), 1 / 3);
    if (dot(n, this.hint(centroid)) < 0) this.idx.push(a, c, b);
    else this.idx.push(a, b, c);
  }

  /** A quad a-b-c-d (in order around it) as two triangles split along the shorter diagonal. */
  quad(a, b, c, d) {
    const ac = len(sub(this.pos[a], this.pos[c]));
    const bd = len(sub(this.pos[b], this.pos[d]));
    if (ac <= bd) {
      this.tri(a, b, c);
      this.tri(a, c, d);
    } else {
      this.tri(a, b, d);
      this.tri(b, c, d);
    }
  }

  /**
   * Adds an (nu+1) x (nv+1) grid of vertices from `f(s, t, i, j)` -> {p, c, info} with s, t in [0, 1]; `wrapU`
   * joins the last column to the first (a closed ring) instead of duplicating it. Returns the index grid.
   */
  grid(nu, nv, f, wrapU = false) {
    const cols = wrapU ? nu : nu + 1;
    /** @type {number[][]} */
    const ids = [];
    for (let j = 0; j <= nv; j++) {
      const row = [];
      for (let i = 0; i < cols; i++) {
        const v = f(i / nu, j / nv, i, j);
        row.push(this.vertex(v.p, v.c, v.info ?? {}, v.np ?? v.p));
      }
      if (wrapU) row.push(row[0]);
      ids.push(row);
    }
    for (let j = 0; j < nv; j++) {
      for (let i = 0; i < nu; i++) this.quad(ids[j][i], ids[j][i + 1], ids[j + 1][i + 1], ids[j + 1][i]);
    }
    return ids;
  }

  get vertexCount() {
    return this.pos.length;
  }
}

/** Area-weighted vertex normals of `positions` (flat V3 list) over the part's triangles. */
export function normals(part, positions = part.npos) {
  const acc = positions.map(() => [0, 0, 0]);
  for (let k = 0; k < part.idx.length; k += 3) {
    const [a, b, c] = [part.idx[k], part.idx[k + 1], part.idx[k + 2]];
    const n = cross(sub(positions[b], positions[a]), sub(positions[c], positions[a]));
    for (const v of [a, b, c]) {
      acc[v][0] += n[0];
      acc[v][1] += n[1];
      acc[v][2] += n[2];
    }
  }
  // Vertices at the same place (grid seams, poles) share one normal, so seams do not show as creases.
  const byKey = new Map();
  positions.forEach((p, i) => {
    const key = p.map((x) => Math.round(x * 1e6)).join(",");
    const list = byKey.get(key);
    if (list) list.push(i);
    else byKey.set(key, [i]);
  });
  const out = positions.map(() => /** @type {V3} */ ([0, 0, 1]));
  for (const list of byKey.values()) {
    const sum = [0, 0, 0];
    for (const i of list) for (let k = 0; k < 3; k++) sum[k] += acc[i][k];
    const l = Math.hypot(sum[0], sum[1], sum[2]);
    const n = /** @type {V3} */ (l > 0 ? [sum[0] / l, sum[1] / l, sum[2] / l] : [0, 0, 1]);
    for (const i of list) out[i] = n;
  }
  return out;
}

/**
 * Finds where a ray from (x, y, +inf) towards -z first meets the part's triangles; returns the z, or `fallback`
 * when it misses. Brute force over every triangle: the generator asks a few thousand times.
 */
export function frontZ(part, x, y, fallback = 0) {
  let best = -Infinity;
  for (let k = 0; k < part.idx.length; k += 3) {
    const a = part.pos[part.idx[k]];
    const b = part.pos[part.idx[k + 1]];
    const c = part.pos[part.idx[k + 2]];
    const det = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1]);
    if (Math.abs(det) < 1e-14) continue;
    const l1 = ((b[1] - c[1]) * (x - c[0]) + (c[0] - b[0]) * (y - c[1])) / det;
    const l2 = ((c[1] - a[1]) * (x - c[0]) + (a[0] - c[0]) * (y - c[1])) / det;
    const l3 = 1 - l1 - l2;
    if (l1 < -1e-9 || l2 < -1e-9 || l3 < -1e-9) continue;
    const z = l1 * a[2] + l2 * b[2] + l3 * c[2];
    if (z > best) best = z;
  }
  return best === -Infinity ? fallback : best;
}

export const add = (a, b) => /** @type {V3} */ ([a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
export const sub = (a, b) => /** @type {V3} */ ([a[0] - b[0], a[1] - b[1], a[2] - b[2]]);
export const scale = (a, k) => /** @type {V3} */ ([a[0] * k, a[1] * k, a[2] * k]);
export const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
export const len = (a) => Math.hypot(a[0], a[1], a[2]);
export const cross = (a, b) =>
  /** @type {V3} */ ([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]);
export const lerp = (a, b, t) => a + (b - a) * t;
export const clamp = (v, lo, hi) => Math.max(lo, Math.min(hi, v));
/** Hermite step from 0 at `e0` to 1 at `e1` (either order). */
export const smoothstep = (e0, e1, x) => {
  const t = clamp((x - e0) / (e1 - e0), 0, 1);
  return t * t * (3 - 2 * t);
};

/** An sRGB hex colour as linear RGB (glTF colours are linear). */
export function linear(hex) {
  const v = [(hex >> 16) & 255, (hex >> 8) & 255, hex & 255].map((c) => c / 255);
  return /** @type {V3} */ (v.map((c) => (c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4))));
}

export function mix3(a, b, t) {
  return /** @type {V3} */ ([lerp(a[0], b[0], t), lerp(a[1], b[1], t), lerp(a[2], b[2], t)]);
}
