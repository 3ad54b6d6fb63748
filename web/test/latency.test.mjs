// @ts-check
//! The status strip's latencies (web/js/panels/latency.js) and the server clock estimate (web/js/link/clock.js):
//! a frame is found by the hub's publish time, the voice figure comes from the observer's message shape
//! (crates/contract/vectors/latency.json).

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { test } from "node:test";

import { ServerClock } from "../js/link/clock.js";
import { Figure, Latencies } from "../js/panels/latency.js";

const vector = JSON.parse(readFileSync(new URL("../../crates/contract/vectors/latency.json", import.meta.url), "utf8"));

test("the clock offset comes from the ping with the shortest round trip", () => {
  const c = new ServerClock();
  assert.equal(c.toPage(1000), null);
  c.sample(100, 140, 5_120); // rtt 40, offset 5_000
  c.sample(200, 202, 5_201); // rtt 2, offset 5_000
  c.sample(300, 360, 5_400); // rtt 60, offset 5_070 (a slow answer, ignored)
  assert.equal(c.offset(), 5_000);
  assert.equal(c.toPage(6_000), 1_000);
});

test("a detection is matched to the frame the page sent just before the hub published it", () => {
  const l = new Latencies();
  const clock = new ServerClock();
  clock.sample(0, 0, 1_000_000); // the server is 1e6 ms ahead
  for (let i = 0; i < 10; i++) l.frameSent(1_000 + i * 66, 1_010 + i * 66);
  // Frame 4 was sent at 1_274 (page), the hub published it 3 ms later; the boxes were drawn at 1_340.
  const ms = l.detectionsDrawn((1_000_000 + 1_277) * 1000, 1_340, (s) => clock.toPage(s));
  assert.equal(ms, 1_340 - (1_000 + 4 * 66));
  assert.equal(l.camera.last, ms);
  // A publish time matching no frame sent (older than the memory, or the clock unknown) records nothing.
  assert.equal(l.detectionsDrawn(5, 2_000, (s) => clock.toPage(s)), null);
  assert.equal(new Latencies().detectionsDrawn(1, 1, () => null), null);
});

test("the voice figure takes the observer's turn messages", () => {
  const l = new Latencies();
  for (const m of vector.messages) l.turn(m);
  const totals = vector.messages.filter((m) => m.kind === "voice").map((m) => m.total_ms);
  assert.ok(totals.length > 0);
  assert.equal(l.voice.last, totals[totals.length - 1]);
  l.turn({ kind: "voice", total_ms: "x" });
  assert.equal(l.voice.values.length, totals.length);
});

test("the stages the server says are behind are shown beside the voice figure, and go when it keeps up", () => {
  const l = new Latencies();
  const slow = vector.messages.find((m) => Array.isArray(m.behind) && m.behind.length > 0);
  assert.ok(slow, "the vectors hold a turn with a stage behind");
  l.turn(slow);
  assert.deepEqual(l.behind, slow.behind);
  assert.ok(l.voiceText().endsWith(`slow: ${slow.behind.join(", ")}`), l.voiceText());
  const quick = vector.messages.find((m) => !m.behind);
  l.turn(quick);
  assert.deepEqual(l.behind, []);
  assert.ok(!l.voiceText().includes("slow"), l.voiceText());
});

test("the voice figure names the engine the welcome says speaks, and an older server's welcome names none", () => {
  const link = JSON.parse(readFileSync(new URL("../../crates/contract/vectors/link.json", import.meta.url), "utf8"));
  const l = new Latencies();
  l.turn(vector.messages.find((m) => !m.behind));
  assert.ok(!l.voiceText().includes("·"), l.voiceText());
  l.speaksWith(link.welcome.voice);
  assert.ok(l.voiceText().endsWith(" · espeak-ng"), l.voiceText());
  l.speaksWith("piper");
  assert.ok(l.voiceText().endsWith(" · Piper"), l.voiceText());
  l.speaksWith(undefined);
  assert.ok(!l.voiceText().includes("·"), l.voiceText());
});

test("a figure shows the last value and the median of the recent ones", () => {
  const f = new Figure();
  assert.equal(f.text(), "–");
  for (const v of [300, 500, 400, 100]) f.add(v);
  assert.equal(f.median(), 350);
  assert.equal(f.text(), "100 ms (median 350)");
  f.add(-1);
  assert.equal(f.values.length, 4);
});
