// @ts-check
/**
 * @file The two latencies the status strip shows, last and median: "speech end -> reply audio", as the server's
 * observer measured the turn (`Agent.latency`), and "camera capture -> box drawn", measured on the page's own clock.
 * A detections message names its frame by the hub's publish time (`frame.ts_us`); on the page's clock (through
 * `ServerClock`) that is just after the page sent the frame, which identifies the frame and so its capture time.
 */

/** Figures the medians are taken over. */
const WINDOW = 31;
/** Frames remembered for matching: about four seconds of camera at 15 fps. */
const FRAMES = 64;
/** The engines' names as the status strip shows them. @type {Record<string, string>} */
const ENGINES = { piper: "Piper", espeak: "espeak-ng" };
/** How far the hub's publish time may be from the page's send time and still be that frame (ms): well under the
 * 66 ms between frames at 15 fps, well over a local link's delay plus the clock estimate's error. */
const MATCH_MS = 30;

export class Figure {
  constructor() {
    /** @type {number[]} */
    this.values = [];
    /** @type {number | null} */
    this.last = null;
  }

  /** @param {number} ms */
  add(ms) {
    if (!Number.isFinite(ms) || ms < 0) return;
    this.last = ms;
    this.values.push(ms);
    if (this.values.length > WINDOW) this.values.shift();
  }

  /** @returns {number | null} */
  median() {
    if (this.values.length === 0) return null;
    const sorted = [...this.values].sort((a, b) => a - b);
    const mid = sorted.length >> 1;
    return sorted.length % 2 ? sorted[mid] : (sorted[mid - 1] + sorted[mid]) / 2;
  }

  /** "312 ms (median 340)", or "–" with nothing measured yet. @returns {string} */
  text() {
    const m = this.median();
    return this.last === null || m === null ? "–" : `${this.last.toFixed(0)} ms (median ${m.toFixed(0)})`;
  }
}

export class Latencies {
  constructor() {
    this.voice = new Figure();
    this.camera = new Figure();
    /** The turn's stages the server says are behind on its machine (`Agent.latency`'s `behind`). @type {string[]} */
    this.behind = [];
    /** The engine that speaks, as the welcome names it (`piper` or `espeak`); null before the welcome. @type {string | null} */
    this.engine = null;
    /** @type {{sentMs: number, captureMs: number}[]} */
    this.frames = [];
  }

  /**
   * The page sent a camera frame captured at `captureMs` (page epoch clock, ms) at `sentMs`.
   * @param {number} captureMs
   * @param {number} sentMs
   */
  frameSent(captureMs, sentMs) {
    this.frames.push({ sentMs, captureMs });
    if (this.frames.length > FRAMES) this.frames.shift();
  }

  /**
   * Detections of the frame the hub published at `frameTsUs` were drawn at `drawnMs` (page clock); `toPage` maps
   * a server time to the page's clock (null while unknown). Returns the latency it recorded, or null.
   * @param {number} frameTsUs
   * @param {number} drawnMs
   * @param {(serverMs: number) => number | null} toPage
   * @returns {number | null}
   */
  detectionsDrawn(frameTsUs, drawnMs, toPage) {
    const published = toPage(frameTsUs / 1000);
    if (published === null) return null;
    let best = null;
    for (const f of this.frames) {
      const gap = Math.abs(published - f.sentMs);
      if (gap <= MATCH_MS && (best === null || gap < Math.abs(published - best.sentMs))) best = f;
    }
    if (best === null) return null;
    const ms = drawnMs - best.captureMs;
    this.camera.add(ms);
    return ms;
  }

  /**
   * One turn as the server's observer measured it (an `Agent.latency` message).
   * @param {unknown} message
   */
  turn(message) {
    const m = /** @type {any} */ (message);
    if (!m || m.kind !== "voice" || !Number.isFinite(m.total_ms)) return;
    this.voice.add(m.total_ms);
    this.behind = Array.isArray(m.behind) ? m.behind.filter((s) => typeof s === "string") : [];
  }

  /**
   * The welcome's `voice`: the engine that speaks the agent's language.
   * @param {unknown} voice
   */
  speaksWith(voice) {
    this.engine = typeof voice === "string" && voice ? voice : null;
  }

  /** The voice figure with the engine and the stages that are behind: "2400 ms (median 900) · Piper · slow:
   * transcription". */
  voiceText() {
    const parts = [this.voice.text()];
    if (this.engine) parts.push(ENGINES[this.engine] ?? this.engine);
    if (this.behind.length) parts.push(`slow: ${this.behind.join(", ")}`);
    return parts.join(" · ");
  }
}
