//! Picks the avatar's renderer: the 3D head (three.js, WebGL 2) where WebGL is hardware-accelerated, else the 2D canvas
//! face (`renderer-choice.js`); `?avatar=2d|3d` asks for one.
//
// The 3D module and three.js are imported only when the 3D head is wanted, so the 2D page loads nothing more
// than before. Without WebGL 2, or when the model or three.js fails to load, the page says so on the console
// and shows the 2D face: a canvas that has had a WebGL context cannot get a 2D one, so it is swapped for a fresh
// copy first.

import { Avatar } from "./avatar.js";
import { chooseRenderer, isSoftwareRenderer } from "./renderer-choice.js";

/**
 * The renderer a page gets without `?avatar=`: its own choice (renderer-choice.js), the 3D head where WebGL is
 * hardware-accelerated and the 2D face on a software rasteriser or without WebGL 2. `?avatar=3d` shows the 3D head
 * on software WebGL too (the lite model there, docs/bench-avatar.md), `?avatar=2d` the 2D face everywhere.
 */
export const DEFAULT_RENDERER = "auto";

/**
 * What this browser's WebGL 2 is: there at all, and a software rasteriser (SwiftShader, llvmpipe: no GPU).
 * @returns {import("./renderer-choice.js").WebglProbe}
 */
export function probeWebgl() {
  try {
    const gl = document.createElement("canvas").getContext("webgl2");
    if (!gl) return { webgl2: false, software: true };
    const info = gl.getExtension("WEBGL_debug_renderer_info");
    const name = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : String(gl.getParameter(gl.RENDERER));
    gl.getExtension("WEBGL_lose_context")?.loseContext();
    return { webgl2: true, software: isSoftwareRenderer(name) };
  } catch {
    return { webgl2: false, software: true };
  }
}

/**
 * The avatar for `canvas`: resolves to {avatar, renderer: "2d" | "3d", canvas} (the canvas may be a new
 * element when a failed 3D start had to be undone). `syncFrames` and `quality`: see Avatar3D.create.
 */
export async function createAvatar(canvas, audioClock, wanted = DEFAULT_RENDERER, { syncFrames = false, quality = {} } = {}) {
  const probe = probeWebgl();
  const choice = chooseRenderer(wanted, probe);
  console.info(`avatar: the ${choice.renderer === "3d" ? "3D head" : "2D face"}: ${choice.reason}`);
  if (choice.renderer === "3d") {
    try {
      const { Avatar3D } = await import("./avatar3d.js");
      const avatar = await Avatar3D.create(canvas, audioClock, null, { syncFrames, quality: { software: probe.software, ...quality } });
      return { avatar, renderer: "3d", canvas, reason: choice.reason };
    } catch (err) {
      console.warn(`avatar: the 3D head could not start (${err?.message ?? err}), showing the 2D face`);
      const fresh = canvas.cloneNode(false);
      canvas.replaceWith(fresh);
      canvas = fresh;
      return { avatar: new Avatar(canvas, audioClock, { syncFrames }), renderer: "2d", canvas, reason: "the 3D head could not start" };
    }
  }
  return { avatar: new Avatar(canvas, audioClock, { syncFrames }), renderer: "2d", canvas, reason: choice.reason };
}
