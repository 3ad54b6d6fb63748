//! The detection overlay on the camera preview: the faces (the person talking in its own colour, names of known
//! people), motion and codes of each `Agent.detections` message.
//
// Detections arrive in the camera frame's pixels (640x360); the preview is mirrored (like a mirror, so moving
// right moves right on screen) and scaled to the card's size, so each point is mapped through the same transform
// (overlay-items.js, which also turns a message into the geometries drawn).

import { frameClock } from "./frame-clock.js";
import { trackCanvasSize } from "./hidpi-canvas.js";
import { detectionItems, frameToCanvas } from "./overlay-items.js";

const FADE_MS = 500;
/** Boxes fade at 15 fps, the camera's own rate. */
const FADE_FRAME_MS = 66;
const COLOURS = { face: "#5fd4c4", speaker: "#ff7ab6", motion: "#f2b86b", motion_centre: "#f2b86b", code: "#7aa2ff" };

export class Overlay {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.last = null;
    this.lastAt = 0;
    this.count = 0;
    this.items = 0;
    this.dirty = false;
    this.w = 0;
    this.h = 0;
    /** Called once per message with boxes, when they are first drawn: (frame.ts_us, drawn at, ms since epoch). */
    this.onDrawn = null;
    this.undrawn = null;
    trackCanvasSize(canvas, this.ctx, (w, h) => {
      this.w = w;
      this.h = h;
      this.dirty = true;
      this.wake?.();
    });
    this.wake = frameClock().add((now) => this.draw(now));
  }

  /** Takes one `Agent.detections` message (the contract's shape); anything else is ignored. */
  show(message) {
    const data = detectionItems(message);
    if (!data) return;
    // An empty message after an empty one changes nothing on the canvas: the vision module sends one per frame.
    const changed = data.items.length > 0 || this.items > 0 || this.last === null;
    this.last = data;
    this.items = data.items.length;
    if (data.items.length > 0 && Number.isFinite(message.frame.ts_us)) this.undrawn = message.frame.ts_us;
    this.lastAt = performance.now();
    this.count += 1;
    if (!changed) return;
    this.dirty = true;
    this.wake();
  }

  /** Draws when something changed (new detections, a resize) and while boxes fade; returns the next frame wanted:
   * the fade's next step, the moment it begins, or none. */
  draw(now) {
    const age = now - this.lastAt;
    if (!this.dirty && (!this.last || age > FADE_MS * 2 + 100)) return Infinity;
    this.paint(now, age);
    if (!this.last || this.items === 0 || age > FADE_MS * 2) return Infinity;
    return age < FADE_MS ? this.lastAt + FADE_MS : now + FADE_FRAME_MS;
  }

  paint(now, age) {
    this.dirty = false;
    const ctx = this.ctx;
    ctx.clearRect(0, 0, this.w, this.h);
    if (!this.last || age > FADE_MS * 2) return;
    ctx.globalAlpha = age < FADE_MS ? 1 : 1 - (age - FADE_MS) / FADE_MS;
    const map = frameToCanvas(this.last.frame, this.w, this.h);
    ctx.lineWidth = 2;
    ctx.font = "600 12px Inter, Segoe UI, Arial, sans-serif";
    for (const item of this.last.items) {
      const colour = COLOURS[item.kind] ?? "#e6e6e6";
      ctx.strokeStyle = colour;
      ctx.fillStyle = colour;
      let labelAt = null;
      if (Array.isArray(item.box) && item.box.length === 4) {
        const [x, y, w, h] = item.box.map(Number);
        const [ax, ay] = map(x, y);
        const [bx, by] = map(x + w, y + h);
        const left = Math.min(ax, bx);
        roundRect(ctx, left, ay, Math.abs(bx - ax), by - ay, 6);
        ctx.stroke();
        labelAt = [left, ay];
      } else if (Array.isArray(item.polygon) && item.polygon.length >= 2) {
        ctx.beginPath();
        item.polygon.forEach(([x, y], i) => {
          const [px, py] = map(Number(x), Number(y));
          if (i === 0) ctx.moveTo(px, py);
          else ctx.lineTo(px, py);
        });
        ctx.closePath();
        ctx.stroke();
        const pts = item.polygon.map(([x, y]) => map(Number(x), Number(y)));
        labelAt = [Math.min(...pts.map((p) => p[0])), Math.min(...pts.map((p) => p[1]))];
      } else if (Array.isArray(item.point) && item.point.length === 2) {
        const [px, py] = map(Number(item.point[0]), Number(item.point[1]));
        ctx.beginPath();
        ctx.arc(px, py, 6, 0, Math.PI * 2);
        ctx.stroke();
        ctx.beginPath();
        ctx.moveTo(px - 11, py);
        ctx.lineTo(px + 11, py);
        ctx.moveTo(px, py - 11);
        ctx.lineTo(px, py + 11);
        ctx.stroke();
        labelAt = [px + 8, py - 8];
      }
      if (labelAt && item.label) label(ctx, String(item.label), labelAt[0], labelAt[1], colour);
    }
    ctx.globalAlpha = 1;
    if (this.undrawn !== null) {
      this.onDrawn?.(this.undrawn, performance.timeOrigin + performance.now());
      this.undrawn = null;
    }
  }
}

function roundRect(ctx, x, y, w, h, r) {
  ctx.beginPath();
  ctx.roundRect(x, y, w, h, Math.min(r, Math.abs(w) / 2, Math.abs(h) / 2));
}

function label(ctx, text, x, y, colour) {
  const shown = text.length > 40 ? `${text.slice(0, 39)}…` : text;
  const w = ctx.measureText(shown).width + 10;
  const top = Math.max(0, y - 18);
  // Keep the label inside the preview even for a geometry at its right edge.
  x = Math.max(0, Math.min(x, ctx.canvas.clientWidth - w));
  ctx.fillStyle = "rgba(8, 12, 18, 0.78)";
  ctx.fillRect(x, top, w, 17);
  ctx.fillStyle = colour;
  ctx.fillText(shown, x + 5, top + 13);
}
