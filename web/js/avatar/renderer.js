//! Picks the avatar's renderer: the 3D head (three.js, WebGL 2; the default) or the 2D canvas face, with `?avatar=2d|3d`.
//
// The 3D module and three.js are imported only when the 3D head is wanted, so the 2D page loads nothing more
// than before. Without WebGL 2, or when the model or three.js fails to load, the page says so on the console
// and shows the 2D face: a canvas that has had a WebGL context cannot get a 2D one, so it is swapped for a fresh
// copy first.

import { Avatar } from "./avatar.js";

/**
 * The renderer a page gets without `?avatar=`: the 3D head, the lite model on software WebGL (bench_avatar keeps
 * it above 30 fps there, docs/bench-avatar.md). `?avatar=2d` keeps the 2D face, and a browser without WebGL 2
 * falls back to it (below).
 */
export const DEFAULT_RENDERER = "3d";

/** Whether this browser can give the 3D head a WebGL 2 context (three.js needs WebGL 2). */
export function webgl2Available() {
  try {
    const gl = document.createElement("canvas").getContext("webgl2");
    if (!gl) return false;
    gl.getExtension("WEBGL_lose_context")?.loseContext();
    return true;
  } catch {
    return false;
  }
}

/**
 * The avatar for `canvas`: resolves to {avatar, renderer: "2d" | "3d", canvas} (the canvas may be a new
 * element when a failed 3D start had to be undone). `syncFrames` and `quality`: see Avatar3D.create.
 */
export async function createAvatar(canvas, audioClock, wanted = DEFAULT_RENDERER, { syncFrames = false, quality = {} } = {}) {
  if (wanted === "3d") {
    if (!webgl2Available()) {
      console.info("avatar: WebGL 2 is not available here, showing the 2D face");
    } else {
      try {
        const { Avatar3D } = await import("./avatar3d.js");
        const avatar = await Avatar3D.create(canvas, audioClock, null, { syncFrames, quality });
        return { avatar, renderer: "3d", canvas };
      } catch (err) {
        console.warn(`avatar: the 3D head could not start (${err?.message ?? err}), showing the 2D face`);
        const fresh = canvas.cloneNode(false);
        canvas.replaceWith(fresh);
        canvas = fresh;
      }
    }
  }
  return { avatar: new Avatar(canvas, audioClock, { syncFrames }), renderer: "2d", canvas };
}
