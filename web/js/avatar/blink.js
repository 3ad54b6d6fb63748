// @ts-check
//! Eyelid motion: blinks in three phases (close, hold, open) at distinct speeds, and the page's own random blinking.
//
// Closing is fast and accelerates, opening is slower and decelerates, as in a real blink. The page blinks on its
// own at random intervals between 450 ms and 4 s until the server sends a blink; then the server owns blinking,
// and if it stays silent for `SERVER_SILENCE_MS` the page takes over again so the face never freezes.

const MIN_INTERVAL_MS = 450;
const MAX_INTERVAL_MS = 4000;
const SERVER_SILENCE_MS = 8000;
export const DEFAULT_PHASES = Object.freeze({ close_ms: 70, hold_ms: 40, open_ms: 150 });

export class BlinkController {
  constructor(random = Math.random) {
    this.random = random;
    this.owner = "page";
    this.lastServerBlink = -Infinity;
    this.current = null; // {start, close, hold, open}
    this.completed = 0;
    this.nextAuto = 0;
    this.openness = 1;
  }

  /** Starts a blink now (`nowMs` on the page clock); `fromServer` hands blinking to the server. */
  blink(nowMs, phases = {}, fromServer = false) {
    if (fromServer) {
      this.owner = "server";
      this.lastServerBlink = nowMs;
    }
    const clamp = (v, d) => (Number.isFinite(v) && v >= 0 && v <= 2000 ? v : d);
    this.current = {
      start: nowMs,
      close: clamp(phases.close_ms, DEFAULT_PHASES.close_ms),
      hold: clamp(phases.hold_ms, DEFAULT_PHASES.hold_ms),
      open: clamp(phases.open_ms, DEFAULT_PHASES.open_ms),
    };
  }

  /** Advances to `nowMs` and returns the eyelid openness from the blink alone (1 open .. 0 closed). */
  update(nowMs) {
    if (this.owner === "server" && nowMs - this.lastServerBlink > SERVER_SILENCE_MS) {
      this.owner = "page";
      this.scheduleAuto(nowMs);
    }
    if (this.owner === "page" && !this.current && nowMs >= this.nextAuto) {
      this.blink(nowMs);
    }
    if (!this.current) {
      this.openness = 1;
      return 1;
    }
    const b = this.current;
    const t = nowMs - b.start;
    let o;
    if (t < b.close) {
      const k = t / Math.max(1, b.close);
      o = 1 - k * k; // ease-in: the lid accelerates as it falls
    } else if (t < b.close + b.hold) {
      o = 0;
    } else if (t < b.close + b.hold + b.open) {
      const k = (t - b.close - b.hold) / Math.max(1, b.open);
      o = 1 - (1 - k) * (1 - k); // ease-out: it slows down as it reaches the top
    } else {
      o = 1;
      this.current = null;
      this.completed += 1;
      if (this.owner === "page") this.scheduleAuto(nowMs);
    }
    this.openness = o;
    return o;
  }

  scheduleAuto(nowMs) {
    this.nextAuto = nowMs + MIN_INTERVAL_MS + this.random() * (MAX_INTERVAL_MS - MIN_INTERVAL_MS);
  }
}
