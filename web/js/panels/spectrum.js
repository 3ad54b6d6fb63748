//! The live microphone spectrum drawn from the server's `Agent.audio.fft` magnitudes (linear, 0..1 full scale).
//
// Bins are grouped on a logarithmic frequency axis (speech lives in the low kilohertz) and shown in dB, with
// falling peaks so short sounds stay visible for a moment.

import { frameClock } from "./frame-clock.js";
import { trackCanvasSize } from "./hidpi-canvas.js";

const BARS = 56;
const FLOOR_DB = -90;
const MIN_HZ = 60;
/** Bars at 15 fps: enough to see speech, and a quarter of the frames of a free-running loop. */
const FRAME_MS = 66;

export class Spectrum {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.levels = new Float32Array(BARS).fill(FLOOR_DB);
    this.peaks = new Float32Array(BARS).fill(FLOOR_DB);
    this.rate = 22050;
    this.size = 1024;
    this.frames = 0;
    this.peakHz = 0;
    this.w = 0;
    this.h = 0;
    trackCanvasSize(canvas, this.ctx, (w, h) => {
      this.w = w;
      this.h = h;
    });
    this.last = performance.now();
    this.wake = frameClock().add((now) => this.draw(now));
  }

  configure(info) {
    if (info && Number.isFinite(info.rate)) this.rate = info.rate;
    if (info && Number.isFinite(info.size)) this.size = info.size;
  }

  /** Takes one spectrum: an ArrayBuffer of f32 little-endian magnitudes, bin k at k * rate / size Hz. */
  push(body) {
    const n = Math.floor(body.byteLength / 4);
    if (n === 0) return;
    const mags = new Float32Array(body, 0, n);
    const nyquist = this.rate / 2;
    let best = 0;
    for (let k = 1; k < n; k++) if (mags[k] > mags[best]) best = k;
    this.peakHz = (best * this.rate) / this.size;
    for (let b = 0; b < BARS; b++) {
      const f0 = MIN_HZ * Math.pow(nyquist / MIN_HZ, b / BARS);
      const f1 = MIN_HZ * Math.pow(nyquist / MIN_HZ, (b + 1) / BARS);
      const k0 = Math.max(1, Math.floor((f0 * this.size) / this.rate));
      const k1 = Math.min(n - 1, Math.max(k0, Math.ceil((f1 * this.size) / this.rate)));
      let m = 0;
      for (let k = k0; k <= k1; k++) m = Math.max(m, mags[k]);
      const db = m > 0 ? Math.max(FLOOR_DB, 20 * Math.log10(m)) : FLOOR_DB;
      this.levels[b] = db;
      if (db > this.peaks[b]) this.peaks[b] = db;
    }
    this.frames += 1;
    this.drawnResting = false;
    this.wake(this.last + FRAME_MS);
  }

  /** Draws the bars at 15 fps while they move; a spectrum at rest (all at the floor) needs no frame until the
   * next one arrives. */
  draw(now) {
    const resting = this.peaks.every((p) => p <= FLOOR_DB);
    if (resting && this.drawnResting) return Infinity;
    this.drawnResting = resting;
    this.paint(now);
    return now + FRAME_MS;
  }

  paint(now) {
    const dt = Math.min(100, now - this.last);
    this.last = now;
    const ctx = this.ctx;
    const { w, h } = this;
    ctx.clearRect(0, 0, w, h);
    const grad = ctx.createLinearGradient(0, h, 0, 0);
    grad.addColorStop(0, "#2f8f9d");
    grad.addColorStop(0.6, "#5fd4c4");
    grad.addColorStop(1, "#f2b86b");
    const gap = 2;
    const bw = (w - gap * (BARS - 1)) / BARS;
    for (let b = 0; b < BARS; b++) {
      // Levels sink back slowly when no new spectrum arrives (microphone stopped).
      this.levels[b] = Math.max(FLOOR_DB, this.levels[b] - dt * 0.08);
      this.peaks[b] = Math.max(this.levels[b], this.peaks[b] - dt * 0.03);
      const x = b * (bw + gap);
      const lh = ((this.levels[b] - FLOOR_DB) / -FLOOR_DB) * h;
      ctx.fillStyle = grad;
      ctx.fillRect(x, h - lh, bw, lh);
      const ph = ((this.peaks[b] - FLOOR_DB) / -FLOOR_DB) * h;
      ctx.fillStyle = "rgba(230, 240, 250, 0.6)";
      ctx.fillRect(x, h - ph - 2, bw, 2);
    }
  }
}
