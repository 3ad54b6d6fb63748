// @ts-check
//! The page's one frame loop: every canvas (the avatar, the overlay, the spectrum) draws through it, at most at
//! its cap, and only when it has something to draw.
//
// On a machine without a GPU every animation frame costs: measured in headless Chromium beside the agent, three
// requestAnimationFrame loops that drew nothing still took 21% of a core (the renderer's main thread and the display
// compositor woken 60 times a second). So nobody here asks for frames in a loop. A drawer says when it next needs a
// frame: soon while it moves (a blink, speech), later while it is calm, never while nothing changes. The clock
// sleeps on a timer until the earliest of those, then asks the browser for one frame. A hidden tab gets no frames
// at all (the browser holds requestAnimationFrame back), so it draws nothing.
//
// What costs is the number of frames the compositor makes, not the pixels: in software each frame composites the
// whole window (hiding the 2D face or the 90-pixel spectrum saved the same 9-10% of a core). The camera preview
// already makes 15 frames a second, so drawing that is not urgent waits for the preview's next frame
// (requestVideoFrameCallback) and rides on it: the canvases' calm updates cost no frame of their own.

/** The page draws at most 30 frames a second: speech and blinks stay smooth at half the cost of 60. */
export const MIN_FRAME_MS = 1000 / 30;
/** A timer this close to a drawer's time asks for the frame now (one vsync's jitter). */
const EARLY_MS = 4;
/** A frame serves every drawer due within half a frame of it, so that drawers at different paces share frames
 * instead of each costing its own. */
const SHARE_MS = MIN_FRAME_MS / 2;
/** A drawer wanting its frame at least this far ahead waits for the pacing video's next frame (15 fps: 66 ms). */
const PACED_FROM_MS = 40;
/** A pacing video that has not delivered a frame this long (stalled, stopped) is passed over for an ordinary frame. */
const PACER_PATIENCE_MS = 150;

/**
 * A drawer: called with the frame's time (ms, page clock), it draws and returns when it next wants a frame
 * (ms, same clock), or Infinity while nothing will change until someone wakes it.
 * @typedef {(now: number) => number} Drawer
 */

/**
 * @typedef {object} Platform
 * @property {(cb: (now: number) => void) => unknown} frame the browser's requestAnimationFrame
 * @property {(cb: () => void, ms: number) => unknown} setTimer setTimeout
 * @property {(handle: unknown) => void} clearTimer clearTimeout
 * @property {() => number} now performance.now
 */

/**
 * Calls back on the pacing video's next frame (with the frame's time, as requestAnimationFrame's); returns false
 * when no video is playing to pace the page.
 * @typedef {(cb: (now: number) => void) => boolean} Pacer
 */

export class FrameClock {
  /** @param {Platform} platform */
  constructor(platform) {
    this.platform = platform;
    /** @type {{ draw: Drawer, due: number }[]} */
    this.drawers = [];
    /** Whether a browser frame has been asked for and has not come yet. */
    this.framePending = false;
    /** @type {unknown} */
    this.timer = null;
    this.timerDue = Infinity;
    /** @type {Pacer | null} */
    this.pacer = null;
    /** Whether the frame asked for waits for the pacing video. */
    this.pendingPaced = false;
    /** The frame asked for: a later request's callback ignores an earlier one's that still comes. */
    this.request = 0;
    /** When the last frame ran (page clock); the next comes at least MIN_FRAME_MS later. */
    this.lastFrame = -Infinity;
    /** Frames run and drawer calls made, for the debug hook and the tests. */
    this.frames = 0;
    this.draws = 0;
  }

  /**
   * Adds a drawer, due at once; returns its `wake(at)`, which brings its next frame forward to `at` (default now).
   * @param {Drawer} draw
   * @returns {(at?: number) => void}
   */
  add(draw) {
    const entry = { draw, due: this.platform.now() };
    this.drawers.push(entry);
    this.schedule();
    return (at = this.platform.now()) => {
      if (at < entry.due) {
        entry.due = at;
        this.schedule();
      }
    };
  }

  /**
   * Lets `pacer` (the camera preview's frames) carry the drawing that is not urgent; null goes back to timers.
   * @param {Pacer | null} pacer
   */
  pace(pacer) {
    this.pacer = pacer;
  }

  /** Asks for one browser frame: the pacing video's when `paced` and one plays, an animation frame otherwise. */
  ask(paced) {
    this.cancelTimer();
    this.framePending = true;
    this.pendingPaced = false;
    const request = ++this.request;
    const run = (/** @type {number} */ now) => {
      if (request === this.request && this.framePending) this.onFrame(now);
    };
    if (paced && this.pacer?.(run)) {
      this.pendingPaced = true;
      // A stalled video must not stall the page: after a while an animation frame serves instead.
      this.timer = this.platform.setTimer(() => {
        this.timer = null;
        if (request === this.request && this.framePending) this.platform.frame(run);
      }, PACER_PATIENCE_MS);
      return;
    }
    this.platform.frame(run);
  }

  /** Sleeps until the earliest due drawer, then asks for one browser frame. */
  schedule() {
    const wanted = Math.min(...this.drawers.map((d) => d.due));
    if (this.framePending) {
      // A frame is on its way; an urgent drawer does not wait for the pacing video's.
      if (this.pendingPaced && wanted - this.platform.now() <= EARLY_MS) this.ask(false);
      return;
    }
    if (!Number.isFinite(wanted)) {
      this.cancelTimer();
      return;
    }
    const due = Math.max(wanted, this.lastFrame + MIN_FRAME_MS);
    const wait = due - this.platform.now();
    if (wait <= EARLY_MS) {
      this.ask(false);
      return;
    }
    if (this.pacer && wait >= PACED_FROM_MS) {
      this.ask(true);
      return;
    }
    if (this.timer !== null && this.timerDue <= due) return;
    this.cancelTimer();
    this.timerDue = due;
    this.timer = this.platform.setTimer(() => {
      this.timer = null;
      this.timerDue = Infinity;
      this.schedule();
    }, wait - EARLY_MS);
  }

  cancelTimer() {
    if (this.timer === null) return;
    this.platform.clearTimer(this.timer);
    this.timer = null;
    this.timerDue = Infinity;
  }

  /** @param {number} now */
  onFrame(now) {
    this.framePending = false;
    this.cancelTimer();
    this.frames += 1;
    this.lastFrame = now;
    for (const d of this.drawers) {
      if (d.due > now + SHARE_MS) continue;
      this.draws += 1;
      let next = Infinity;
      try {
        next = d.draw(now);
      } catch (err) {
        // One broken canvas must not stop the others; it is retried at its calm pace.
        console.error("a drawer failed", err);
        next = now + 1000;
      }
      d.due = Number.isNaN(next) ? Infinity : Math.max(next, now + MIN_FRAME_MS);
    }
    this.schedule();
  }
}

/** The browser's platform for a FrameClock. */
export function browserPlatform() {
  return {
    frame: (/** @type {(now: number) => void} */ cb) => requestAnimationFrame(cb),
    setTimer: (/** @type {() => void} */ cb, /** @type {number} */ ms) => setTimeout(cb, ms),
    clearTimer: (/** @type {any} */ h) => clearTimeout(h),
    now: () => performance.now(),
  };
}

/** The page's frame clock, shared by every canvas. */
let shared = null;
export function frameClock() {
  if (!shared) shared = new FrameClock(browserPlatform());
  return shared;
}
