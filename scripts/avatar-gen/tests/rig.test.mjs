//! Unit tests of the 3D head's pure modules: viseme blending on the audio clock and the rig's mapping.
// @ts-check
// Run: node --test scripts/avatar-gen/tests/ (web/js/package.json marks the page's .js files as ES modules).

import { test } from "node:test";
import assert from "node:assert/strict";
import { VisemeMixer, LAG_S } from "../../../web/js/avatar/viseme-mix.js";
import { rig, mouthOpen, dominant } from "../../../web/js/avatar/rig3d.js";
import { expression } from "../../../web/js/avatar/moods.js";
import { BlinkController } from "../../../web/js/avatar/blink.js";

const rest = { eyeX: 0, eyeY: 0, yaw: 0, pitch: 0 };
const sum = (w) => Object.values(w).reduce((a, b) => a + b, 0);

test("a mixer with no cues rests on silence", () => {
  assert.deepEqual(new VisemeMixer().weights(12.3), { sil: 1 });
});

test("a cue's shape is fully on within 40 ms of its audio time and weights always sum to one", () => {
  const m = new VisemeMixer();
  m.add(1, 10, [{ t_ms: 0, v: "sil" }, { t_ms: 100, v: "aa" }, { t_ms: 300, v: "O" }, { t_ms: 500, v: "sil" }]);
  assert.ok(LAG_S <= 0.04);
  for (let t = 9.9; t < 10.8; t += 0.005) {
    const w = new VisemeMixer();
    w.add(1, 10, [{ t_ms: 0, v: "sil" }, { t_ms: 100, v: "aa" }, { t_ms: 300, v: "O" }, { t_ms: 500, v: "sil" }]);
    assert.ok(Math.abs(sum(w.weights(t)) - 1) < 1e-9, `weights at ${t} sum to ${sum(w.weights(t))}`);
  }
  assert.equal(m.weights(10.1 + 0.04).aa, 1);
  assert.equal(m.weights(10.3 + 0.04).O, 1);
});

test("blending anticipates the next cue: the mouth starts moving shortly before it", () => {
  const m = new VisemeMixer();
  m.add(1, 0, [{ t_ms: 0, v: "sil" }, { t_ms: 200, v: "aa" }]);
  const before = m.weights(0.19).aa ?? 0;
  assert.ok(before > 0 && before < 0.5, `aa at 10 ms before its cue: ${before}`);
  assert.equal(m.weights(0.15).aa ?? 0, 0);
});

test("fast cues blend into each other instead of skipping", () => {
  const m = new VisemeMixer();
  m.add(1, 0, [{ t_ms: 0, v: "PP" }, { t_ms: 30, v: "aa" }, { t_ms: 60, v: "PP" }]);
  const mid = m.weights(0.03);
  assert.ok((mid.PP ?? 0) > 0 && (mid.aa ?? 0) > 0, JSON.stringify(mid));
});

test("the last cue holds briefly, then the mouth returns to rest and the cues are forgotten", () => {
  const m = new VisemeMixer();
  m.add(1, 0, [{ t_ms: 0, v: "O" }]);
  assert.equal(m.weights(0.05).O, 1);
  assert.equal(m.weights(0.5).sil, 1);
  assert.equal(m.pending, 0);
});

test("clearing an utterance stops its visemes and keeps the others", () => {
  const m = new VisemeMixer();
  m.add(1, 0, [{ t_ms: 0, v: "aa" }, { t_ms: 5000, v: "sil" }]);
  m.add(2, 0, [{ t_ms: 0, v: "U" }, { t_ms: 5000, v: "sil" }]);
  m.clear(1);
  assert.equal(dominant(m.weights(1)), "U");
  m.clear();
  assert.deepEqual(m.weights(1), { sil: 1 });
});

test("malformed cues are skipped", () => {
  const m = new VisemeMixer();
  // @ts-ignore: wrong on purpose
  m.add(1, 0, [null, { t_ms: "x", v: "aa" }, { t_ms: 0, v: 3 }, { t_ms: 0, v: "E" }]);
  assert.equal(m.pending, 1);
});

test("mouth opening matches the 2D face's jaw for the same visemes and mood", () => {
  const neutral = expression("neutral");
  assert.equal(mouthOpen({ aa: 1 }, neutral), 0.85);
  assert.equal(mouthOpen({ sil: 1 }, neutral), 0);
  assert.ok(Math.abs(mouthOpen({ aa: 0.5, O: 0.5 }, neutral) - 0.725) < 1e-9);
  // A surprised face's own jaw shows only in silence.
  assert.equal(mouthOpen({ sil: 1 }, expression("surprised")), 0.35);
});

test("eye rotation follows the gaze direction's sign, and the head turns the same way by less", () => {
  const left = rig({ gaze: { eyeX: -0.8, eyeY: 0, yaw: -0.3, pitch: 0 }, blink: 1, mood: expression("neutral"), visemes: { sil: 1 }, nowMs: 0 });
  const right = rig({ gaze: { eyeX: 0.8, eyeY: 0, yaw: 0.3, pitch: 0 }, blink: 1, mood: expression("neutral"), visemes: { sil: 1 }, nowMs: 0 });
  assert.ok(left.eyes.yaw < 0 && right.eyes.yaw > 0);
  assert.ok(left.head.yaw < 0 && right.head.yaw > 0);
  assert.ok(Math.abs(right.head.yaw) < Math.abs(right.eyes.yaw) + 0.2);
  const down = rig({ gaze: { eyeX: 0, eyeY: 0.8, yaw: 0, pitch: 0.3 }, blink: 1, mood: expression("neutral"), visemes: { sil: 1 }, nowMs: 0 });
  assert.ok(down.eyes.pitch > 0, "looking down is a positive pitch (three.js x rotation)");
  assert.ok(down.morphs.eyeBlinkLeft > 0, "looking down lowers the lids a little");
});

test("a closed blink closes both lids fully; moods become morph combinations", () => {
  const shut = rig({ gaze: rest, blink: 0, mood: expression("neutral"), visemes: { sil: 1 }, nowMs: 0 });
  assert.equal(shut.morphs.eyeBlinkLeft, 1);
  assert.equal(shut.morphs.eyeBlinkRight, 1);
  const happy = rig({ gaze: rest, blink: 1, mood: expression("happy"), visemes: { sil: 1 }, nowMs: 0 }).morphs;
  assert.ok(happy.mouthSmileLeft > 0.9 && happy.eyeSquintLeft > 0 && happy.mouthFrownLeft === 0);
  const sad = rig({ gaze: rest, blink: 1, mood: expression("sad"), visemes: { sil: 1 }, nowMs: 0 }).morphs;
  assert.ok(sad.browInnerUp > 0.8 && sad.mouthFrownLeft > 0.5 && sad.mouthSmileLeft === 0);
  const angry = rig({ gaze: rest, blink: 1, mood: expression("angry"), visemes: { sil: 1 }, nowMs: 0 }).morphs;
  assert.ok(angry.browDownLeft > 0.7);
  const surprised = rig({ gaze: rest, blink: 1, mood: expression("surprised"), visemes: { sil: 1 }, nowMs: 0 }).morphs;
  assert.ok(surprised.eyeWideLeft > 0 && surprised.browOuterUpLeft === 1 && surprised.jawOpen > 0.3);
  assert.ok(surprised.viseme_O > 0.2, "a surprised mouth opens round");
  const speaking = rig({ gaze: rest, blink: 1, mood: expression("surprised"), visemes: { aa: 1 }, nowMs: 0 }).morphs;
  assert.ok(!speaking.viseme_O && !speaking.jawOpen, "while speaking the visemes alone shape the mouth");
});

test("thinking is lopsided: one brow up and one down, one mouth corner up", () => {
  const m = rig({ gaze: rest, blink: 1, mood: expression("thinking"), visemes: { sil: 1 }, nowMs: 0 }).morphs;
  assert.ok(m.browOuterUpLeft > m.browOuterUpRight + 0.5, `brows ${m.browOuterUpLeft} vs ${m.browOuterUpRight}`);
  assert.ok(m.browDownRight > m.browDownLeft, `brows down ${m.browDownRight} vs ${m.browDownLeft}`);
  assert.ok(m.mouthSmileLeft > 0.3 && m.mouthSmileRight === 0, `smile ${m.mouthSmileLeft} / ${m.mouthSmileRight}`);
  const eyes = rig({ gaze: rest, blink: 1, mood: expression("thinking"), visemes: { sil: 1 }, nowMs: 0 }).eyes;
  assert.ok(eyes.pitch < -0.05 && Math.abs(eyes.yaw) > 0.05, "thinking glances up and aside");
  // Every other mood stays symmetric.
  for (const name of ["neutral", "happy", "sad", "surprised", "angry", "listening"]) {
    const s = rig({ gaze: rest, blink: 1, mood: expression(name), visemes: { sil: 1 }, nowMs: 0 }).morphs;
    assert.equal(s.browOuterUpLeft, s.browOuterUpRight, name);
    assert.equal(s.mouthSmileLeft, s.mouthSmileRight, name);
  }
});

test("idle motion keeps the head moving a little, never far", () => {
  const yaws = [];
  for (let t = 0; t < 60000; t += 250) yaws.push(rig({ gaze: rest, blink: 1, mood: expression("neutral"), visemes: { sil: 1 }, nowMs: t }).head.yaw);
  const span = Math.max(...yaws) - Math.min(...yaws);
  assert.ok(span > 0.01 && span < 0.08, `idle yaw spans ${span} rad`);
});

test("page blinks come every 450 ms to 4 s and close faster than they open", () => {
  let seed = 1;
  const rnd = () => ((seed = (seed * 16807) % 2147483647) / 2147483647);
  const b = new BlinkController(rnd);
  const starts = [];
  let was = false;
  let closeMs = 0;
  let openMs = 0;
  let prev = 1;
  for (let t = 0; t < 120000; t += 5) {
    const o = b.update(t);
    if (b.current && !was) starts.push(b.current.start);
    was = b.current !== null;
    if (o < prev) closeMs += 5;
    if (o > prev) openMs += 5;
    prev = o;
  }
  assert.ok(starts.length > 40, `${starts.length} blinks in two minutes`);
  for (let i = 1; i < starts.length; i++) {
    const gap = starts[i] - starts[i - 1] - 260; // a default blink lasts 70 + 40 + 150 ms
    assert.ok(gap >= 450 - 5 && gap <= 4000 + 5, `gap ${gap} ms between blinks`);
  }
  assert.ok(closeMs < openMs, `closing took ${closeMs} ms in all, opening ${openMs} ms`);
});
