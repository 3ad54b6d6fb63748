//! Writes the avatar's models, assets/avatar.glb and assets/avatar-lite.glb, from the design in head.mjs; `--check` only compares.
// @ts-check
//
// Usage: node scripts/avatar-gen/make-avatar.mjs [--check] [--out DIR]
// The GLBs are committed; `--check` (run by the tests) fails when regenerating them would change a byte, so the
// committed files are always what this code produces. avatar-lite.glb is the same design at half the grid
// resolution (a third of the triangles), which the page draws on software WebGL (docs: ARCHITECTURE.md, 3D avatar).

import { readFileSync, writeFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { buildAvatar, MODELS } from "./head.mjs";
import { writeGlb } from "./glb.mjs";

const root = join(dirname(fileURLToPath(import.meta.url)), "..", "..");
const args = process.argv.slice(2);
const check = args.includes("--check");
const outAt = args.indexOf("--out");
const dir = outAt >= 0 ? args[outAt + 1] : join(root, "assets");

let stale = false;
for (const { file, detail } of MODELS) {
  const out = join(dir, file);
  const bytes = writeGlb(buildAvatar({ detail }));
  if (!check) {
    writeFileSync(out, bytes);
    console.log(`avatar: wrote ${out} (${bytes.length} bytes)`);
    continue;
  }
  let old;
  try {
    old = readFileSync(out);
  } catch (err) {
    console.error(`avatar: ${out} is missing (${err.message}); run node scripts/avatar-gen/make-avatar.mjs`);
    stale = true;
    continue;
  }
  if (Buffer.compare(old, Buffer.from(bytes)) !== 0) {
    console.error(`avatar: ${out} differs from what the generator makes now (${old.length} vs ${bytes.length} bytes)`);
    stale = true;
  } else {
    console.log(`avatar: ${out} is up to date (${bytes.length} bytes)`);
  }
}
if (stale) process.exit(1);
