// @ts-check
//! The overlay's pure functions against the contract's detections vectors (crates/contract/vectors/detections.json).

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { test } from "node:test";

import { detectionItems, frameToCanvas, personLabel } from "../js/panels/overlay-items.js";

const vectors = JSON.parse(readFileSync(new URL("../../crates/contract/vectors/detections.json", import.meta.url), "utf8"));
const [full, empty, otherDetector] = vectors.messages;

test("every face, moving region, moving centre and code of a message becomes one geometry", () => {
  const out = detectionItems(full);
  assert.ok(out);
  assert.deepEqual(out.frame, { width: full.frame.width, height: full.frame.height });
  const faces = out.items.filter((i) => i.kind === "face" || i.kind === "speaker");
  assert.deepEqual(
    faces.map((f) => f.box),
    full.faces.map((f) => [f.x, f.y, f.w, f.h]),
  );
  const regions = out.items.filter((i) => i.kind === "motion");
  assert.equal(regions.length, full.motion.regions.length);
  const centre = out.items.find((i) => i.kind === "motion_centre");
  assert.deepEqual(centre?.point, [full.motion.centre.x, full.motion.centre.y]);
  const code = out.items.find((i) => i.kind === "code");
  assert.equal(code?.label, full.codes[0].text);
  assert.deepEqual(
    code?.polygon,
    full.codes[0].polygon.map((p) => [p.x, p.y]),
  );
});

test("the person talking is drawn as the speaker, labelled with the name the agent knows", () => {
  const out = detectionItems(full);
  assert.ok(out);
  const speaker = out.items.find((i) => i.kind === "speaker");
  const talking = full.people.find((p) => p.speaking);
  assert.deepEqual(speaker?.box, [talking.face.x, talking.face.y, talking.face.w, talking.face.h]);
  assert.equal(speaker?.label, "Anna · talking · smiling");
  const other = out.items.find((i) => i.kind === "face");
  assert.equal(other?.label, "face · looking away");
  assert.equal(personLabel({ face: { x: 0, y: 0, w: 1, h: 1 }, name: null }), "face");
});

test("a frame with nothing seen draws nothing and still counts as a message", () => {
  const out = detectionItems(empty);
  assert.ok(out);
  assert.deepEqual(out.items, []);
});

test("another detector's message without gaze or figures is drawn at its own frame size", () => {
  const out = detectionItems(otherDetector);
  assert.ok(out);
  assert.deepEqual(out.frame, { width: 1280, height: 720 });
  assert.equal(out.items.length, 1);
});

test("messages that are not detections are refused", () => {
  assert.equal(detectionItems(null), null);
  assert.equal(detectionItems({ items: [{ kind: "face", box: [1, 2, 3, 4] }] }), null);
  assert.equal(detectionItems({ frame: { width: 0, height: 360 } }), null);
});

test("a code whose payload is not text is labelled with its kind", () => {
  const msg = structuredClone(full);
  msg.codes[0].text = null;
  const code = detectionItems(msg)?.items.find((i) => i.kind === "code");
  assert.equal(code?.label, "qr");
});

test("frame pixels map onto a mirrored cover-fitted canvas", () => {
  // A 640x360 frame on a 320x180 canvas: half scale, no crop, mirrored.
  const map = frameToCanvas({ width: 640, height: 360 }, 320, 180);
  assert.deepEqual(map(0, 0), [320, 0]);
  assert.deepEqual(map(640, 360), [0, 180]);
  // A square canvas crops the sides: the frame's centre stays in the middle.
  const square = frameToCanvas({ width: 640, height: 360 }, 360, 360);
  assert.deepEqual(square(320, 180), [180, 180]);
  // A face on the frame's left (the person's right) is drawn on the canvas's right, like a mirror.
  const [x] = map(100, 100);
  assert.ok(x > 160);
});
