//! Writes the avatar's model, assets/avatar.glb, from the design in head.mjs; `--check` only compares.
// @ts-check
//
// Usage: node scripts/avatar-gen/make-avatar.mjs [--check] [--out PATH]
// The GLB is committed; `--check` (run by the tests) fails when regenerating it would change a byte, so the
// committed file is always what this code produces.

import { readFileSync, writeFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { buildAvatar } from "./head.mjs";
import { writeGlb } from "./glb.mjs";

const root = join(dirname(fileURLToPath(import.meta.url)), "..", "..");
const args = process.argv.slice(2);
const check = args.includes("--check");
const outAt = args.indexOf("--out");
const out = outAt >= 0 ? args[outAt + 1] : join(root, "assets", "avatar.glb");

const bytes = writeGlb(buildAvatar());
if (check) {
  let old;
  try {
    old = readFileSync(out);
  } catch (err) {
    console.error(`avatar: ${out} is missing (${err.message}); run node scripts/avatar-gen/make-avatar.mjs`);
    process.exit(1);
  }
  if (Buffer.compare(old, Buffer.from(bytes)) !== 0) {
    console.error(`avatar: ${out} differs from what the generator makes now (${old.length} vs ${bytes.length} bytes)`);
    process.exit(1);
  }
  console.log(`avatar: ${out} is up to date (${bytes.length} bytes)`);
} else {
  writeFileSync(out, bytes);
  console.log(`avatar: wrote ${out} (${bytes.length} bytes)`);
}
