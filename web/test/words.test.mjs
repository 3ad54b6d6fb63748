// @ts-check
//! The page's words: every language has every word, the language is chosen as documented, and values fill in.

import assert from "node:assert/strict";
import { test } from "node:test";

import { WORDS, fill, pickLanguage, wordsFor } from "../js/panels/words.js";

test("every language has every word, none of them empty", () => {
  const keys = Object.keys(WORDS.en).sort();
  for (const [language, words] of Object.entries(WORDS)) {
    assert.deepEqual(Object.keys(words).sort(), keys, language);
    for (const [key, value] of Object.entries(words)) assert.ok(value.trim().length > 0, `${language}.${key}`);
  }
  // Italian is not English with another name: the controls read differently.
  assert.notEqual(wordsFor("it").startMicrophone, wordsFor("en").startMicrophone);
});

test("the query parameter wins over the agent's language, and unknown languages fall back", () => {
  assert.equal(pickLanguage("it", "en"), "it");
  assert.equal(pickLanguage(null, "it"), "it");
  assert.equal(pickLanguage("fr", "it"), "it");
  assert.equal(pickLanguage(undefined, "de"), "en");
  assert.equal(pickLanguage(null, null), "en");
});

test("placeholders are filled from the values given, and others are kept", () => {
  assert.equal(fill(WORDS.it.saved, { name: "a.mcap", messages: 12 }), "salvato a.mcap (12 messaggi)");
  assert.equal(fill("{name} {other}", { name: "x" }), "x {other}");
});
