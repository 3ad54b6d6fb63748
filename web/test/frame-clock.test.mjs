// @ts-check
//! The page's one frame loop (web/js/panels/frame-clock.js), on a simulated clock: frames only when a drawer wants
//! one, never above the cap, none at all while every drawer is at rest.
import { test } from "node:test";
import assert from "node:assert/strict";
import { FrameClock, MIN_FRAME_MS } from "../js/panels/frame-clock.js";

/** A simulated browser: timers and animation frames (every 1000/60 ms, like a display) on a virtual clock. */
function simulated() {
  let now = 0;
  /** @type {{ at: number, cb: () => void, id: number }[]} */
  let timers = [];
  /** @type {((now: number) => void)[]} */
  let frameCallbacks = [];
  let nextId = 1;
  let frameRequests = 0;
  const platform = {
    frame: (/** @type {(now: number) => void} */ cb) => {
      frameRequests += 1;
      frameCallbacks.push(cb);
    },
    setTimer: (/** @type {() => void} */ cb, /** @type {number} */ ms) => {
      const id = nextId++;
      timers.push({ at: now + Math.max(0, ms), cb, id });
      return id;
    },
    clearTimer: (/** @type {unknown} */ id) => {
      timers = timers.filter((t) => t.id !== id);
    },
    now: () => now,
  };
  /** Runs the virtual clock to `end` ms: timers when due, animation frames on each vsync. */
  function run(end) {
    const vsync = 1000 / 60;
    while (now < end) {
      // Counted in whole frames, so that rounding never lands a vsync on the present instant again.
      const nextVsync = Math.max(1, Math.ceil(now / vsync + 1e-9)) * vsync;
      const timer = timers.reduce((a, t) => (a === null || t.at < a.at ? t : a), /** @type {any} */ (null));
      if (timer && timer.at <= nextVsync) {
        now = Math.max(now, timer.at);
        timers = timers.filter((t) => t !== timer);
        timer.cb();
        continue;
      }
      now = nextVsync;
      const cbs = frameCallbacks;
      frameCallbacks = [];
      for (const cb of cbs) cb(now);
    }
  }
  return { platform, run, frames: () => frameRequests, time: () => now };
}

test("a drawer at rest gets no frames, and a wake brings one at once", () => {
  const sim = simulated();
  const clock = new FrameClock(sim.platform);
  /** @type {number[]} */
  const drawn = [];
  const wake = clock.add((now) => {
    drawn.push(now);
    return Infinity;
  });
  sim.run(1000);
  assert.equal(drawn.length, 1, "only the first frame, when it was added");
  assert.equal(sim.frames(), 1, "no animation frame is asked for while nothing changes");
  wake();
  sim.run(1100);
  assert.equal(drawn.length, 2);
  assert.ok(drawn[1] - 1000 < 20, `drawn ${drawn[1] - 1000} ms after the wake`);
});

test("a busy drawer is held to the cap, and a calm one to about its own pace, sharing the busy one's frames", () => {
  const sim = simulated();
  const clock = new FrameClock(sim.platform);
  let busy = 0;
  let calm = 0;
  clock.add((now) => {
    busy += 1;
    return now; // as often as allowed
  });
  clock.add((now) => {
    calm += 1;
    return now + 100;
  });
  sim.run(3000);
  const cap = 3000 / MIN_FRAME_MS;
  assert.ok(busy <= cap + 1 && busy >= cap * 0.6, `busy drew ${busy} frames in 3 s, cap ${cap}`);
  assert.ok(calm <= 31 && calm >= 20, `calm drew ${calm} frames in 3 s at 10 fps`);
  assert.ok(sim.frames() <= cap + 1, `${sim.frames()} animation frames asked for: the calm drawer shares frames`);
});

test("two drawers at different paces never take the page above the cap together", () => {
  const sim = simulated();
  const clock = new FrameClock(sim.platform);
  clock.add((now) => now + 40);
  clock.add((now) => now + 66);
  sim.run(3000);
  assert.ok(sim.frames() <= 3000 / MIN_FRAME_MS + 1, `${sim.frames()} frames in 3 s`);
});

test("a drawer that wants a frame later sleeps on a timer, not on animation frames", () => {
  const sim = simulated();
  const clock = new FrameClock(sim.platform);
  /** @type {number[]} */
  const drawn = [];
  clock.add((now) => {
    drawn.push(now);
    return drawn.length < 3 ? now + 500 : Infinity;
  });
  sim.run(2000);
  assert.equal(drawn.length, 3);
  assert.equal(sim.frames(), 3, "one animation frame per drawing");
  assert.ok(Math.abs(drawn[1] - drawn[0] - 500) < 20, `${drawn[1] - drawn[0]} ms between frames`);
});

test("a wake for a later time does not delay a frame already due sooner", () => {
  const sim = simulated();
  const clock = new FrameClock(sim.platform);
  let n = 0;
  const wake = clock.add((now) => {
    n += 1;
    return now + 200;
  });
  sim.run(10);
  wake(5000);
  sim.run(450);
  assert.equal(n, 3, "drawn at 0, about 200 and about 400 ms");
});

test("a drawer that throws does not stop the others", () => {
  const sim = simulated();
  const clock = new FrameClock(sim.platform);
  const errors = console.error;
  console.error = () => {};
  try {
    let good = 0;
    clock.add(() => {
      throw new Error("broken canvas");
    });
    clock.add((now) => {
      good += 1;
      return now + 100;
    });
    sim.run(1000);
    assert.ok(good >= 8, `the healthy drawer drew ${good} frames`);
  } finally {
    console.error = errors;
  }
});
