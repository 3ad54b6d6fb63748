// @ts-check
//! Where the avatar looks: the eyes jump to a target quickly (a saccade), the head follows more slowly and by less.
//
// Targets come in camera-image coordinates (0..1, origin top-left). The avatar faces the person the camera sees,
// so image-left is the avatar's left, which is the viewer's right: x is mirrored.

const EYE_TAU_MS = 18; // the eyes settle in ~40-60 ms
const HEAD_TAU_MS = 380; // the head takes about a second
const HEAD_SHARE = 0.45; // the head turns by less than the eyes point
const IDLE_AFTER_MS = 5000;

export class GazeController {
  constructor(random = Math.random) {
    this.random = random;
    this.target = { x: 0.5, y: 0.5 };
    this.dir = { x: 0, y: 0 }; // wanted direction, -1..1, x positive = viewer's right
    this.eye = { x: 0, y: 0 };
    this.head = { x: 0, y: 0 };
    this.commands = 0;
    this.lastCommand = -Infinity;
    this.nextIdle = 0;
    this.idleOffset = { x: 0, y: 0 };
  }

  /** Looks at image point (`x`, `y`) in [0,1]; values outside are clamped. */
  look(nowMs, x, y) {
    const cx = Math.max(0, Math.min(1, x));
    const cy = Math.max(0, Math.min(1, y));
    this.target = { x: cx, y: cy };
    this.dir = { x: (0.5 - cx) * 2, y: (cy - 0.5) * 2 };
    this.idleOffset = { x: 0, y: 0 };
    this.commands += 1;
    this.lastCommand = nowMs;
  }

  /** Advances by `dtMs`; returns {eyeX, eyeY, yaw, pitch} for the face. */
  update(nowMs, dtMs) {
    // Without commands the eyes make small idle saccades around the current direction, so the face stays alive.
    if (nowMs - this.lastCommand > IDLE_AFTER_MS && nowMs >= this.nextIdle) {
      this.idleOffset = { x: (this.random() - 0.5) * 0.35, y: (this.random() - 0.5) * 0.2 };
      this.nextIdle = nowMs + 1200 + this.random() * 2200;
    }
    const want = { x: this.dir.x + this.idleOffset.x, y: this.dir.y + this.idleOffset.y };
    const ke = 1 - Math.exp(-dtMs / EYE_TAU_MS);
    const kh = 1 - Math.exp(-dtMs / HEAD_TAU_MS);
    this.eye.x += (want.x - this.eye.x) * ke;
    this.eye.y += (want.y - this.eye.y) * ke;
    this.head.x += (want.x * HEAD_SHARE - this.head.x) * kh;
    this.head.y += (want.y * HEAD_SHARE - this.head.y) * kh;
    return {
      // The eyes rotate with the head, so their offset inside the face is what the head has not done yet.
      eyeX: clamp(this.eye.x - this.head.x * 0.6, -1, 1),
      eyeY: clamp(this.eye.y - this.head.y * 0.6, -1, 1),
      yaw: clamp(this.head.x, -1, 1),
      pitch: clamp(this.head.y, -1, 1),
    };
  }
}

function clamp(v, lo, hi) {
  return Math.max(lo, Math.min(hi, v));
}
