// @ts-check
//! Which renderer a page draws its avatar with, from what was asked (`?avatar=`) and what this browser's WebGL is
//! (issue 47, docs/avatar.md): the 3D head costs a software rasteriser (SwiftShader, llvmpipe: no GPU, as on many
//! robot and kiosk computers and in every headless test) more than one core, the 2D face a fraction, on the machine
//! that also runs the agent. So the page picks the 3D head on its own only where WebGL is hardware-accelerated;
//! `?avatar=3d` asks for it anyway, `?avatar=2d` never draws it. Pure.

/**
 * @typedef {{webgl2: boolean, software: boolean}} WebglProbe what this browser's WebGL 2 is: there at all, and a
 *   software rasteriser
 * @typedef {{renderer: "2d" | "3d", reason: string}} Choice
 */

/**
 * The renderer for `wanted` (`"2d"`, `"3d"`, or anything else: the page's own choice) given `probe`.
 * @param {string | null} wanted
 * @param {WebglProbe} probe
 * @returns {Choice}
 */
export function chooseRenderer(wanted, probe) {
  if (wanted === "2d") return { renderer: "2d", reason: "asked for (?avatar=2d)" };
  if (!probe.webgl2) return { renderer: "2d", reason: "WebGL 2 is not available here" };
  if (wanted === "3d") return { renderer: "3d", reason: "asked for (?avatar=3d)" };
  if (probe.software) {
    return {
      renderer: "2d",
      reason: "WebGL here is a software rasteriser (no GPU): the 3D head would take a core; ?avatar=3d shows it anyway",
    };
  }
  return { renderer: "3d", reason: "WebGL is hardware-accelerated" };
}

/**
 * Whether a WebGL renderer's name is a software rasteriser.
 * @param {string} name `UNMASKED_RENDERER_WEBGL` (or `RENDERER` where that is hidden)
 */
export function isSoftwareRenderer(name) {
  return /swiftshader|llvmpipe|softpipe|software/i.test(name);
}
