// @ts-check
//! The avatar's renderer choice (web/js/avatar/renderer-choice.js): the 3D head by itself only on a GPU.

import assert from "node:assert/strict";
import { test } from "node:test";
import { chooseRenderer, isSoftwareRenderer } from "../js/avatar/renderer-choice.js";

const gpu = { webgl2: true, software: false };
const software = { webgl2: true, software: true };
const none = { webgl2: false, software: true };

test("the page shows the 3D head by itself only where WebGL is hardware-accelerated", () => {
  assert.equal(chooseRenderer(null, gpu).renderer, "3d");
  assert.equal(chooseRenderer(null, software).renderer, "2d");
  assert.match(chooseRenderer(null, software).reason, /software rasteriser/);
  assert.equal(chooseRenderer("auto", none).renderer, "2d");
});

test("asking for a renderer gets it where it can run", () => {
  assert.equal(chooseRenderer("3d", software).renderer, "3d");
  assert.equal(chooseRenderer("3d", none).renderer, "2d");
  assert.equal(chooseRenderer("2d", gpu).renderer, "2d");
});

test("software rasterisers are told from GPUs by their renderer's name", () => {
  for (const name of [
    "ANGLE (Google, Vulkan 1.3.0 (SwiftShader Device (Subzero) (0x0000C0DE)), SwiftShader driver)",
    "llvmpipe (LLVM 15.0.6, 256 bits)",
    "softpipe",
  ]) {
    assert.equal(isSoftwareRenderer(name), true, name);
  }
  for (const name of ["ANGLE (Intel, Mesa Intel(R) UHD Graphics 620 (KBL GT2), OpenGL 4.6)", "Apple M2", "NVIDIA GeForce RTX 3060/PCIe/SSE2"]) {
    assert.equal(isSoftwareRenderer(name), false, name);
  }
});
