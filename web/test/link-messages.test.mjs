// @ts-check
//! The page link's welcome and status messages (crates/contract/vectors/link.json) carry what the page reads of them.

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { test } from "node:test";

import { HEADER_BYTES } from "../js/link/frames.js";

const { welcome, status } = JSON.parse(
  readFileSync(new URL("../../crates/contract/vectors/link.json", import.meta.url), "utf8"),
);

test("the welcome names the media formats the page captures in", () => {
  assert.equal(welcome.type, "welcome");
  // The capture worklet resamples to this rate and cuts 20 ms chunks: 441 samples of s16 mono.
  assert.equal(welcome.audio.rate, 22050);
  assert.equal(welcome.audio.format, "s16le");
  assert.equal((welcome.audio.rate * welcome.audio.chunk_ms) / 1000, 441);
  assert.deepEqual([welcome.video.width, welcome.video.height], [640, 360]);
  assert.equal(welcome.fft.bins * 2, welcome.fft.size);
  assert.ok(HEADER_BYTES > 0);
});

test("the status carries the counters the status strip shows", () => {
  assert.equal(status.type, "status");
  for (const key of ["video_queue", "not_holder", "to_page"]) assert.equal(typeof status.dropped[key], "number");
  assert.equal(typeof status.advice.video_fps, "number");
  assert.equal(typeof status.in.audio_fps, "number");
});

test("the welcome names the agent's language, one the page has words for", async () => {
  const { WORDS } = await import("../js/panels/words.js");
  assert.ok(Object.hasOwn(WORDS, welcome.language), welcome.language);
});
