// @ts-check
//! The loopback playback route's delay measurement (web/js/media/playback-delay.js): the loudness envelope of what
//! the player sends, matched against the envelope of what comes out of the route, gives the delay the viseme
//! schedule is shifted by.

import assert from "node:assert/strict";
import { test } from "node:test";

import {
  DelayEstimator,
  EnvelopeTrack,
  FRAME_S,
  HeardShift,
  JitterTrack,
  MATCH_FRAMES,
  SHIFT_SLEW,
  bestLag,
} from "../js/media/playback-delay.js";

/** A speech-like signal: bursts of a 150 Hz tone of varying loudness and length, with pauses, `seconds` long. */
function speechLike(rate, seconds, seed = 1) {
  let x = seed;
  const random = () => {
    x = (x * 16807) % 2147483647;
    return x / 2147483647;
  };
  const out = new Float32Array(Math.round(rate * seconds));
  let i = 0;
  while (i < out.length) {
    const burst = Math.round(rate * (0.05 + 0.25 * random()));
    const level = random() < 0.3 ? 0 : 0.1 + 0.5 * random();
    for (let k = 0; k < burst && i < out.length; k++, i++) out[i] = level * Math.sin((2 * Math.PI * 150 * i) / rate);
  }
  return out;
}

test("an envelope frame is the mean magnitude of the samples that fall in it", () => {
  const t = new EnvelopeTrack();
  const rate = 1000; // 5 samples a frame
  t.add([1, -1, 1, -1, 1, 0.5, -0.5, 0.5, -0.5, 0.5], 10 * FRAME_S, rate);
  const f = t.frames(9, 4);
  assert.equal(f[0], 0); // never seen: silence
  assert.ok(Math.abs(f[1] - 1) < 1e-6);
  assert.ok(Math.abs(f[2] - 0.5) < 1e-6);
  assert.equal(f[3], 0);
});

test("a received envelope delayed by 23.5 frames is found at that lag", () => {
  const rate = 8000;
  const sig = speechLike(rate, 3);
  const sent = new EnvelopeTrack();
  const got = new EnvelopeTrack();
  const delay = 23.5 * FRAME_S;
  sent.add(sig, 1.0, rate);
  // What comes out: the same sound later, quieter, with a little noise (a codec's changes).
  const out = sig.map((v, i) => 0.7 * v + 0.01 * Math.sin(i * 1.7));
  got.add(out, 1.0 + delay, rate);
  const upTo = Math.floor((1.0 + delay + 2.8) / FRAME_S);
  const from = upTo - MATCH_FRAMES + 1;
  const m = bestLag(sent.frames(from - 60, MATCH_FRAMES + 60), got.frames(from, MATCH_FRAMES), 60);
  assert.ok(m && m.score > 0.95, JSON.stringify(m));
  assert.ok(Math.abs(m.lag - 23.5) < 0.6, `lag ${m.lag}`);
});

test("silence and unrelated sound give no match", () => {
  const quiet = new Float32Array(MATCH_FRAMES);
  const noise = Float32Array.from({ length: MATCH_FRAMES + 60 }, (_, i) => Math.abs(Math.sin(i * 12.9898) * 43758.5453) % 1);
  assert.equal(bestLag(noise, quiet, 60), null);
  const other = Float32Array.from({ length: MATCH_FRAMES }, (_, i) => Math.abs(Math.sin(i * 78.233) * 12345.678) % 1);
  const m = bestLag(noise, other, 60);
  assert.ok(!m || m.score < 0.8, JSON.stringify(m));
});

test("the estimator matches each stretch once and keeps the median, the initial guess before any", () => {
  const rate = 8000;
  const e = new DelayEstimator(0.06);
  assert.equal(e.delayS, 0.06);
  const sig = speechLike(rate, 8, 7);
  e.sent.add(sig, 0, rate);
  e.received.add(sig, 0.1, rate);
  const second = Math.round(1 / FRAME_S);
  const found = [];
  for (let upTo = 3 * second; upTo < 8 * second; upTo += 20) {
    const m = e.match(upTo);
    if (m) found.push(m.delayS);
  }
  // One match per half window at most (400 frames of 5 ms: every second), each at the 100 ms delay.
  assert.ok(found.length >= 3 && found.length <= 6, `${found.length} matches`);
  for (const d of found) assert.ok(Math.abs(d - 0.1) < 0.003, `delay ${d}`);
  assert.ok(Math.abs(e.delayS - 0.1) < 0.003);
});

test("the jitter buffer's mean over a stretch takes the readings in it and the one that covers its end", () => {
  const j = new JitterTrack();
  assert.equal(j.latestS, null);
  assert.equal(j.meanOver(0, 1), null);
  for (let k = 0; k < 8; k++) j.add(k * 0.25, 0.05 + 0.01 * k);
  j.add(2.5, Number.NaN); // a reading the receiver could not give is left out
  assert.ok(Math.abs(j.latestS - 0.12) < 1e-9);
  // Readings at 0.5, 0.75, 1.0 and the one at 1.25 that covers the end of 1.1.
  assert.ok(Math.abs(j.meanOver(0.5, 1.1) - (0.07 + 0.08 + 0.09 + 0.1) / 4) < 1e-9);
  assert.equal(j.meanOver(5, 6), null);
});

test("a jitter buffer that grows mid-speech moves the delay at once, without waiting for new matches", () => {
  const rate = 8000;
  const e = new DelayEstimator(0.09);
  const sig = speechLike(rate, 8, 3);
  // 40 ms of fixed delay plus a 55 ms buffer while the stretches are matched.
  e.sent.add(sig, 0, rate);
  e.received.add(sig, 0.095, rate);
  for (let t = 0; t <= 8; t += 0.25) e.jitter.add(t, 0.055);
  const second = Math.round(1 / FRAME_S);
  for (let upTo = 3 * second; upTo < 8 * second; upTo += 20) e.match(upTo);
  assert.ok(e.measured.length >= 3);
  assert.ok(Math.abs(e.delayS - 0.095) < 0.003, `delay ${e.delayS}`);
  // The machine gets busy and the receiver's buffer grows to 190 ms: the delay follows its reading.
  e.jitter.add(8.25, 0.19);
  assert.ok(Math.abs(e.delayS - 0.23) < 0.003, `delay ${e.delayS}`);
});

test("without jitter-buffer readings the delay is the median of the matches", () => {
  const rate = 8000;
  const e = new DelayEstimator(0.09);
  const sig = speechLike(rate, 8, 5);
  e.sent.add(sig, 0, rate);
  e.received.add(sig, 0.12, rate);
  const second = Math.round(1 / FRAME_S);
  for (let upTo = 3 * second; upTo < 8 * second; upTo += 20) e.match(upTo);
  assert.ok(Math.abs(e.delayS - 0.12) < 0.003, `delay ${e.delayS}`);
});

test("the heard clock's shift jumps while nothing plays and never runs the clock backwards while speech does", () => {
  const h = new HeardShift();
  assert.equal(h.follow(1.0, 0.09, false), 0.09);
  // Speech plays and the delay jumps by 100 ms: the shift follows at SHIFT_SLEW, so heard time keeps rising.
  let heard = 1.0 - 0.09;
  let now = 1.0;
  for (let k = 1; k <= 40; k++) {
    now = 1.0 + k / 60;
    const next = now - h.follow(now, 0.19, true);
    assert.ok(next >= heard, `heard clock went back at ${now}: ${next} < ${heard}`);
    heard = next;
  }
  assert.ok(Math.abs(h.s - 0.19) < 1e-9, `shift ${h.s}`);
  // It took 100 ms / SHIFT_SLEW of audio time to get there, and the history tells what was in effect when.
  assert.equal(h.at(0.5), 0.09);
  assert.ok(Math.abs(h.at(1.0 + 0.1 / SHIFT_SLEW / 2) - 0.14) < 0.01, `halfway ${h.at(1.1)}`);
  assert.equal(h.at(now), 0.19);
});

test("a shift history on a clock that went back starts again, so a later clock's shifts are found", () => {
  const h = new HeardShift();
  // Drawn on the page's clock before the audio context existed: no route, no shift.
  h.follow(5.3, 0, false);
  // The context's clock starts from 0; speech through the loopback begins there.
  h.follow(1.2, 0.07, false);
  assert.equal(h.at(1.5), 0.07);
  assert.equal(h.at(0.5), 0.07, "before the first shift on this clock: that shift");
});

test("before any match the delay is the guessed fixed part plus the jitter buffer's reading, if there is one", () => {
  const e = new DelayEstimator(0.09, 0.035);
  assert.equal(e.delayS, 0.09);
  e.jitter.add(0.25, 0.2);
  assert.ok(Math.abs(e.delayS - 0.235) < 1e-9, `delay ${e.delayS}`);
  assert.equal(new DelayEstimator(0.09).delayS, 0.09, "no fixed guess: the initial one");
});

test("a match made while the receiver gave no reading does not stop the delay following the buffer", () => {
  const e = new DelayEstimator(0.09, 0.035);
  e.measured = [0.1, 0.1, 0.1];
  e.fixed = [0.04, null, 0.04];
  e.jitter.add(1, 0.2);
  assert.ok(Math.abs(e.delayS - 0.24) < 1e-9, `delay ${e.delayS}`);
  e.fixed = [null, null, null];
  assert.ok(Math.abs(e.delayS - 0.1) < 1e-9, "no match with a reading: the matches' median");
});
