// @ts-check
//! The link's binary frame layout against the server's codec (crates/contract/vectors/frames.json, written by the
//! server's `frame_vectors_match_the_link_codec` test).

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { test } from "node:test";

import { decodeFrame, decodeSpeech, encodeFrame, HEADER_BYTES, KIND } from "../js/link/frames.js";

const vectors = JSON.parse(readFileSync(new URL("../../crates/contract/vectors/frames.json", import.meta.url), "utf8"));
const frame = (name) => vectors.frames.find((f) => f.name === name);
const bytes = (hex) => new Uint8Array(hex.match(/../g).map((h) => parseInt(h, 16)));
const hexOf = (buffer) => Buffer.from(new Uint8Array(buffer)).toString("hex");

test("the header is the server's: size and kinds", () => {
  assert.equal(HEADER_BYTES, vectors.header_bytes);
  assert.equal(KIND.AUDIO, frame("audio").kind);
  assert.equal(KIND.VIDEO, frame("video").kind);
  assert.equal(KIND.SPEECH, frame("speech").kind);
  assert.equal(KIND.SPECTRUM, frame("spectrum").kind);
});

test("the page encodes microphone and camera frames byte for byte as the server parses them", () => {
  const audio = frame("audio");
  assert.equal(hexOf(encodeFrame(KIND.AUDIO, audio.seq, new Int16Array(audio.pcm))), audio.hex);
  const video = frame("video");
  assert.equal(hexOf(encodeFrame(KIND.VIDEO, video.seq, bytes(video.payload_hex))), video.hex);
});

test("the page decodes the server's speech and spectrum frames", () => {
  const speech = frame("speech");
  const f = decodeFrame(bytes(speech.hex).buffer);
  assert.ok(f);
  assert.equal(f.kind, KIND.SPEECH);
  assert.equal(f.seq, speech.seq);
  const s = decodeSpeech(f.body);
  assert.ok(s);
  assert.equal(s.utterance, speech.utterance);
  assert.equal(s.offset, speech.offset);
  assert.deepEqual([...s.pcm], speech.pcm);
  const spectrum = frame("spectrum");
  const g = decodeFrame(bytes(spectrum.hex).buffer);
  assert.equal(g?.kind, KIND.SPECTRUM);
  assert.deepEqual([...new Float32Array(g.body)], spectrum.bins);
});

test("a frame of another version or too short is refused", () => {
  const b = bytes(frame("audio").hex);
  b[1] = 2;
  assert.equal(decodeFrame(b.buffer), null);
  assert.equal(decodeFrame(new ArrayBuffer(3)), null);
});
