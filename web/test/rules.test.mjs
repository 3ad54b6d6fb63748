// @ts-check
//! The rule trace's messages (crates/contract/vectors/rules.json) carry what the page's rule panel shows.

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { test } from "node:test";

const vectors = JSON.parse(readFileSync(new URL("../../crates/contract/vectors/rules.json", import.meta.url), "utf8"));

test("a rule change names its time, program, rule path, actions and reasons", () => {
  for (const m of vectors.messages) {
    assert.equal(typeof m.ts_ms, "number");
    assert.equal(typeof m.program, "string");
    assert.match(m.rule, /^[a-z_]+\.[a-z_]+( > [a-z_]+\.[a-z_]+)*$/);
    assert.equal(typeof m.action, "string");
    assert.ok(Array.isArray(m.because) && m.because.every((b) => typeof b === "string"));
  }
});
