// @ts-check
//! The avatar's pure modules against the contract's avatar vectors (crates/contract/vectors/avatar.json): visemes on the
//! audio clock, the three blink phases, and where the eyes and the head turn.

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { test } from "node:test";

import { BlinkController } from "../js/avatar/blink.js";
import { GazeController } from "../js/avatar/gaze.js";
import { VisemeTrack } from "../js/avatar/viseme-track.js";
import { VISEMES } from "../js/avatar/visemes.js";

const vectors = JSON.parse(readFileSync(new URL("../../crates/contract/vectors/avatar.json", import.meta.url), "utf8"));
const byCmd = (cmd) => vectors.commands.find((c) => c.cmd === cmd);

test("the page knows every viseme the contract names", () => {
  assert.deepEqual([...VISEMES].sort(), [...vectors.visemes].sort());
});

test("visemes play on the audio clock from the utterance's first sample", () => {
  const cmd = byCmd("visemes");
  const track = new VisemeTrack();
  const start = 10.0; // audio-clock seconds at which sample 0 plays
  track.add(cmd.utterance, start, cmd.items);
  for (const item of cmd.items.slice(0, -1)) {
    assert.equal(track.at(start + item.t_ms / 1000 + 0.001), item.v, `at ${item.t_ms} ms`);
  }
  // Before the first cue the mouth rests; long after the last it rests again.
  assert.equal(new VisemeTrack().at(start), "sil");
  assert.equal(track.at(start + 5), "sil");
});

test("a barge-in clears one utterance's visemes and keeps the others", () => {
  const cmd = byCmd("visemes");
  const track = new VisemeTrack();
  track.add(cmd.utterance, 0, cmd.items);
  track.add(cmd.utterance + 1, 0, [{ t_ms: 100, v: "E" }]);
  track.clear(byCmd("speech_stop").utterance);
  assert.equal(track.at(0.101), "E");
});

test("a server blink closes, holds and opens at its own speeds", () => {
  const cmd = byCmd("blink");
  const b = new BlinkController(() => 0.5);
  b.blink(1000, cmd, true);
  assert.equal(b.owner, "server");
  assert.ok(b.update(1000 + cmd.close_ms / 2) < 1, "closing");
  assert.equal(b.update(1000 + cmd.close_ms + cmd.hold_ms / 2), 0, "closed");
  const opening = b.update(1000 + cmd.close_ms + cmd.hold_ms + cmd.open_ms / 2);
  assert.ok(opening > 0 && opening < 1, "opening");
  assert.equal(b.update(1000 + cmd.close_ms + cmd.hold_ms + cmd.open_ms + 1), 1, "open again");
  assert.equal(b.completed, 1);
});

test("the page blinks on its own every 450 ms to 4 s until the server does", () => {
  for (const r of [0, 0.5, 0.999]) {
    const b = new BlinkController(() => r);
    b.scheduleAuto(0);
    assert.ok(b.nextAuto >= 450 && b.nextAuto <= 4000, `${b.nextAuto}`);
  }
});

test("a target on the right of the camera image turns eyes and head to the viewer's left, eyes first", () => {
  const cmd = byCmd("gaze");
  assert.ok(cmd.x > 0.5);
  const g = new GazeController(() => 0.5);
  g.look(0, cmd.x, cmd.y);
  const early = g.update(40, 40);
  assert.ok(early.eyeX < -0.3, `eyes lead: ${early.eyeX}`);
  assert.ok(early.yaw > -0.2, `the head has barely turned: ${early.yaw}`);
  let later = early;
  for (let t = 80; t <= 2000; t += 40) later = g.update(t, 40);
  assert.ok(later.yaw < -0.3, `the head follows: ${later.yaw}`);
});
