// @ts-check
//! The microphone resampler: 48 kHz and 44.1 kHz input become 22050 Hz with the tone's pitch and level kept and
//! what lies above the new Nyquist frequency removed instead of folded back.

import assert from "node:assert/strict";
import { test } from "node:test";

import { OUT_RATE, Resampler } from "../js/media/resampler.js";

/** Resamples `seconds` of a sine of `hz` at `inRate`, fed in 128-sample blocks as an AudioWorklet gets them. */
function resampleTone(inRate, hz, seconds, amplitude = 0.5) {
  const r = new Resampler(inRate);
  const out = [];
  const total = Math.round(inRate * seconds);
  for (let start = 0; start < total; start += 128) {
    const block = new Float32Array(Math.min(128, total - start));
    for (let i = 0; i < block.length; i++) block[i] = amplitude * Math.sin((2 * Math.PI * hz * (start + i)) / inRate);
    r.write(block);
    r.drain((s) => out.push(s));
  }
  return out;
}

const rms = (xs) => Math.sqrt(xs.reduce((a, x) => a + x * x, 0) / xs.length);
const crossings = (xs) => xs.slice(1).filter((x, i) => (xs[i] < 0) !== (x < 0)).length;

for (const inRate of [48000, 44100]) {
  test(`a 1 kHz tone at ${inRate} Hz keeps its pitch and level at 22050 Hz`, () => {
    const out = resampleTone(inRate, 1000, 1.0);
    assert.ok(Math.abs(out.length - OUT_RATE) < 100, `${out.length} samples for one second`);
    const steady = out.slice(500, out.length - 500);
    const hz = crossings(steady) / 2 / (steady.length / OUT_RATE);
    assert.ok(Math.abs(hz - 1000) < 5, `${hz} Hz`);
    assert.ok(Math.abs(rms(steady) - 0.5 / Math.SQRT2) < 0.02, `rms ${rms(steady)}`);
  });

  test(`a 15 kHz tone at ${inRate} Hz, above the new Nyquist frequency, is removed rather than folded`, () => {
    const out = resampleTone(inRate, 15000, 0.5);
    assert.ok(rms(out.slice(200, out.length - 200)) < 0.01, `rms ${rms(out)}`);
  });
}

test("stereo input is mixed to mono", () => {
  const r = new Resampler(44100);
  const left = new Float32Array(4096).fill(0.5);
  const right = new Float32Array(4096).fill(-0.5);
  const out = [];
  r.write(left, right);
  r.drain((s) => out.push(s));
  assert.ok(out.length > 0);
  assert.ok(out.every((s) => Math.abs(s) < 1e-6));
});
