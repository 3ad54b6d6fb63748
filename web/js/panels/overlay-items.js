// @ts-check
//! What the overlay draws for one `Agent.detections` message, and where: pure functions, unit-tested against the
//! contract's JSON vectors (crates/contract/vectors/detections.json, web/test/overlay-items.test.mjs).

/**
 * @typedef {{x: number, y: number, w: number, h: number}} Box
 * @typedef {{x: number, y: number}} Point
 * @typedef {{seq?: number, ts_us?: number, width: number, height: number}} Frame
 * @typedef {{kind: string, text?: string | null, polygon?: Point[]}} Code
 * @typedef {{moving: boolean, centre?: Point | null, regions?: Box[]}} Motion
 * @typedef {{face: Box, looking?: boolean, smiling?: boolean, speaking?: boolean, name?: string | null}} Person
 * @typedef {{frame: Frame, faces?: Box[] | null, people?: Person[] | null, motion?: Motion | null,
 *   codes?: Code[] | null}} Detections
 * @typedef {{kind: "face" | "speaker" | "motion" | "motion_centre" | "code", box?: number[], polygon?: number[][],
 *   point?: number[], label?: string}} Item
 */

/**
 * The geometries of a detections message in frame pixels: a box per face (a `speaker` box for the person talking,
 * labelled with the person's name when the agent knows them, and whether they smile or look away), a box per
 * moving region and a point at the moving centre, a polygon per code labelled with its text (or its kind when the
 * payload is not text).
 * Returns null for a message that is not a detections message (no frame size).
 * @param {unknown} message
 * @returns {{frame: {width: number, height: number}, items: Item[]} | null}
 */
export function detectionItems(message) {
  const m = /** @type {Detections} */ (message);
  if (!m || typeof m !== "object" || !m.frame || !(m.frame.width > 0) || !(m.frame.height > 0)) return null;
  /** @type {Item[]} */
  const items = [];
  /** @type {Map<string, Person>} */
  const people = new Map();
  for (const p of m.people ?? []) {
    if (p && isBox(p.face)) people.set(boxKey(p.face), p);
  }
  for (const f of m.faces ?? []) {
    if (!isBox(f)) continue;
    const person = people.get(boxKey(f));
    items.push({
      kind: person?.speaking ? "speaker" : "face",
      box: [f.x, f.y, f.w, f.h],
      label: person ? personLabel(person) : "face",
    });
  }
  const motion = m.motion;
  if (motion && motion.moving) {
    for (const r of motion.regions ?? []) {
      if (isBox(r)) items.push({ kind: "motion", box: [r.x, r.y, r.w, r.h] });
    }
    if (motion.centre && isPoint(motion.centre)) {
      items.push({ kind: "motion_centre", point: [motion.centre.x, motion.centre.y] });
    }
  }
  for (const c of m.codes ?? []) {
    const polygon = (c.polygon ?? []).filter(isPoint).map((p) => [p.x, p.y]);
    if (polygon.length >= 2) {
      items.push({ kind: "code", polygon, label: typeof c.text === "string" ? c.text : c.kind });
    }
  }
  return { frame: { width: m.frame.width, height: m.frame.height }, items };
}

/**
 * Maps frame pixels to canvas pixels for a preview drawn with `object-fit: cover` and mirrored horizontally (like
 * a mirror: moving right moves right on screen).
 * @param {{width: number, height: number}} frame
 * @param {number} canvasW
 * @param {number} canvasH
 * @returns {(x: number, y: number) => [number, number]}
 */
export function frameToCanvas(frame, canvasW, canvasH) {
  const s = Math.max(canvasW / frame.width, canvasH / frame.height);
  const ox = (canvasW - frame.width * s) / 2;
  const oy = (canvasH - frame.height * s) / 2;
  return (x, y) => [canvasW - (ox + x * s), oy + y * s];
}

/**
 * What the overlay writes by a person's face: their name (or "face"), then "talking", "smiling", "looking away".
 * @param {Person} p
 */
export function personLabel(p) {
  const parts = [typeof p.name === "string" && p.name ? p.name : "face"];
  if (p.speaking) parts.push("talking");
  if (p.smiling) parts.push("smiling");
  if (p.looking === false) parts.push("looking away");
  return parts.join(" · ");
}

/** @param {Box} b */
function boxKey(b) {
  return `${b.x},${b.y},${b.w},${b.h}`;
}

/** @param {any} b */
function isBox(b) {
  return b && [b.x, b.y, b.w, b.h].every(Number.isFinite) && b.w > 0 && b.h > 0;
}

/** @param {any} p */
function isPoint(p) {
  return p && Number.isFinite(p.x) && Number.isFinite(p.y);
}
