// @ts-check
//! The page's playback start, put on the server's clock (web/js/media/played.js).
import { test } from "node:test";
import assert from "node:assert/strict";
import { playedMessage } from "../js/media/played.js";

test("an utterance scheduled ahead is heard at its anchor plus the route's delay, on the server's clock", () => {
  // Sample 0 enters the route 60 ms from now and the loopback plays 40 ms behind: heard 100 ms from now.
  const m = playedMessage(7, 10.06, 0.04, 10.0, 1_000_000, 250);
  assert.ok(m);
  assert.equal(m.type, "played");
  assert.equal(m.utterance, 7);
  assert.ok(Math.abs(m.at_ms - (1_000_000 + 100 + 250)) < 1e-6, String(m.at_ms));
});

test("nothing is said before the server's clock is known, nor for unframed speech", () => {
  assert.equal(playedMessage(7, 10, 0, 10, 1_000_000, null), null);
  assert.equal(playedMessage(0, 10, 0, 10, 1_000_000, 5), null);
  assert.equal(playedMessage(7, Number.NaN, 0, 10, 1_000_000, 5), null);
});
