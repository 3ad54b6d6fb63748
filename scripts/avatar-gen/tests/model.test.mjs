//! Tests of the avatar generator: the GLB is valid, reproducible, committed as generated, and its targets move.
// @ts-check

import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { fileURLToPath } from "node:url";
import { buildAvatar, MODELS, VISEME_NAMES } from "../head.mjs";
import { writeGlb, readGlb, accessorFloats } from "../glb.mjs";

const committed = fileURLToPath(new URL("../../../assets/avatar.glb", import.meta.url));
const bytes = writeGlb(buildAvatar());
const glb = readGlb(bytes);
const LITE = MODELS.find((m) => m.file === "avatar-lite.glb");
const liteBytes = writeGlb(buildAvatar({ detail: LITE?.detail }));

const mesh = (name) => {
  const m = glb.json.meshes.find((x) => x.name === name);
  assert.ok(m, `mesh ${name}`);
  return m;
};

/** Largest displacement (m) of target `name` on primitive `prim` of mesh `m`, and its mean y displacement. */
function moves(m, prim, name) {
  const i = m.extras.targetNames.indexOf(name);
  assert.ok(i >= 0, `${m.name} has target ${name}`);
  const d = accessorFloats(glb, m.primitives[prim].targets[i].POSITION);
  let max = 0;
  let minY = 0;
  for (let k = 0; k < d.length; k += 3) {
    max = Math.max(max, Math.hypot(d[k], d[k + 1], d[k + 2]));
    minY = Math.min(minY, d[k + 1]);
  }
  return { max, minY };
}

test("the generator is deterministic and the committed assets/avatar.glb is exactly what it makes", () => {
  assert.equal(Buffer.compare(Buffer.from(writeGlb(buildAvatar())), Buffer.from(bytes)), 0);
  assert.equal(Buffer.compare(readFileSync(committed), Buffer.from(bytes)), 0,
    "assets/avatar.glb is stale: run node scripts/avatar-gen/make-avatar.mjs");
});

test("the committed assets/avatar-lite.glb is exactly what the generator makes at its detail", () => {
  assert.ok(LITE && LITE.detail < 1);
  const path = fileURLToPath(new URL(`../../../assets/${LITE.file}`, import.meta.url));
  assert.equal(Buffer.compare(readFileSync(path), Buffer.from(liteBytes)), 0,
    "assets/avatar-lite.glb is stale: run node scripts/avatar-gen/make-avatar.mjs");
});

test("the lite model has the same nodes, meshes, materials and targets with at most 40% of the triangles", () => {
  const lite = readGlb(liteBytes);
  const shape = (g) => ({
    nodes: g.json.nodes.map((n) => n.name),
    meshes: g.json.meshes.map((m) => [m.name, m.primitives.length, m.extras?.targetNames ?? []]),
    materials: g.json.materials.map((m) => m.name),
  });
  assert.deepEqual(shape(lite), shape(glb));
  const triangles = (g) => g.json.meshes.flatMap((m) => m.primitives).reduce((n, p) => n + g.json.accessors[p.indices].count / 3, 0);
  assert.ok(triangles(lite) <= 0.4 * triangles(glb), `${triangles(lite)} of ${triangles(glb)} triangles`);
  // The features sit where they do on the full model: the eyes (placed on the fine skull) have not moved.
  const eyes = (g) => g.json.nodes.filter((n) => n.name.startsWith("Eye")).map((n) => n.translation);
  assert.deepEqual(eyes(lite), eyes(glb));
});

test("the model is a glTF 2.0 binary with the nodes the page drives", () => {
  assert.equal(glb.json.asset.version, "2.0");
  const names = glb.json.nodes.map((n) => n.name);
  for (const n of ["Avatar", "Head", "Body", "Neck", "EyeLeft", "EyeRight", "Face", "Mouth", "Lids", "Brows", "Hair"]) {
    assert.ok(names.includes(n), `node ${n}`);
  }
  const eyes = glb.json.nodes.filter((n) => n.name.startsWith("Eye"));
  assert.ok(eyes[0].translation[0] > 0 && eyes[1].translation[0] < 0, "the left eye is on +x (the viewer's right)");
  for (const acc of glb.json.accessors) assert.ok(acc.count > 0);
});

test("face and mouth carry the 15 Oculus visemes and the expression targets", () => {
  assert.equal(VISEME_NAMES.length, 15);
  for (const name of ["Face", "Mouth"]) {
    const t = mesh(name).extras.targetNames;
    for (const v of VISEME_NAMES) assert.ok(t.includes(`viseme_${v}`), `${name} has viseme_${v}`);
    for (const x of ["jawOpen", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight"]) assert.ok(t.includes(x));
  }
  assert.deepEqual(mesh("Lids").extras.targetNames.filter((n) => n.startsWith("eyeBlink")), ["eyeBlinkLeft", "eyeBlinkRight"]);
  assert.ok(mesh("Brows").extras.targetNames.includes("browInnerUp"));
  // Every primitive of a mesh has one target per name (glTF requires it).
  for (const m of glb.json.meshes) for (const p of m.primitives) assert.equal((p.targets ?? []).length, (m.extras?.targetNames ?? []).length);
});

test("open visemes drop the lower lip far more than closed ones, and silence moves nothing", () => {
  const mouth = mesh("Mouth");
  const aa = moves(mouth, 0, "viseme_aa");
  const pp = moves(mouth, 0, "viseme_PP");
  const sil = moves(mouth, 0, "viseme_sil");
  assert.ok(aa.minY < -0.012, `aa drops the lower lip by ${-aa.minY} m`);
  assert.ok(pp.minY > -0.004, `PP drops it by ${-pp.minY} m`);
  assert.equal(sil.max, 0);
  // The skin of the chin follows the jaw.
  assert.ok(moves(mesh("Face"), 0, "viseme_aa").minY < -0.01);
});

test("a blink brings each upper lid down over its eye, and only that eye's", () => {
  const lids = mesh("Lids");
  const i = lids.extras.targetNames.indexOf("eyeBlinkLeft");
  const base = accessorFloats(glb, lids.primitives[0].attributes.POSITION);
  const d = accessorFloats(glb, lids.primitives[0].targets[i].POSITION);
  let leftDown = 0;
  let rightMoved = 0;
  for (let k = 0; k < d.length; k += 3) {
    if (base[k] > 0) leftDown = Math.min(leftDown, d[k + 1]);
    else rightMoved = Math.max(rightMoved, Math.abs(d[k + 1]));
  }
  assert.ok(leftDown < -0.01, `left upper lid comes down ${-leftDown} m`);
  assert.equal(rightMoved, 0);
});
