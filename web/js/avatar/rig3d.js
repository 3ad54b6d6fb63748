// @ts-check
//! The 3D head's rig: turns the avatar's controllers (gaze, blink, mood, visemes) into morph weights and rotations.
//
// Pure functions, so the mapping is unit-tested without a browser. Angles are radians in three.js's frame (the
// head looks along +z, +x is the viewer's right): a positive yaw turns the eyes or head towards the viewer's
// right, a positive pitch looks down.

import { mouthShape } from "./visemes.js";

export const EYE_YAW_RAD = 0.42; // eye offset 1 in the gaze controller's units
export const EYE_PITCH_RAD = 0.3;
export const HEAD_YAW_RAD = 0.38;
export const HEAD_PITCH_RAD = 0.22;

/**
 * Morph weights and rotations for one frame.
 * `gaze`: {eyeX, eyeY, yaw, pitch} from GazeController.update; `blink`: eyelid openness from the blink alone
 * (1 open .. 0 closed); `mood`: the blended expression (moods.js keys); `visemes`: {name: weight};
 * `nowMs`: page time, for idle motion.
 */
export function rig({ gaze, blink, mood, visemes, nowMs }) {
  /** @type {Record<string, number>} */
  const m = {};
  for (const [v, w] of Object.entries(visemes)) if (v !== "sil" && w > 0) m[`viseme_${v}`] = w;
  const silent = visemes.sil ?? 0;

  // The mood's own jaw (surprise) shows only while the mouth is not speaking, as on the 2D face.
  m.jawOpen = Math.max(0, mood.jaw) * silent;
  // A surprised mouth opens round, not just down: part of the "O" shape with the mood's jaw.
  if (mood.jaw > 0.2) m.viseme_O = (m.viseme_O ?? 0) + silent * Math.min(1, mood.jaw) * 0.7;
  const smile = mood.smile;
  const asym = mood.asym ?? 0;
  m.mouthSmileLeft = m.mouthSmileRight = Math.max(0, smile);
  m.mouthFrownLeft = m.mouthFrownRight = Math.max(0, -smile);
  // Thinking: the mouth pulled up on the avatar's left only, down on its right.
  m.mouthSmileLeft = clamp01(m.mouthSmileLeft + 0.45 * asym);
  m.mouthFrownRight = clamp01(m.mouthFrownRight + 0.35 * asym);

  // Brows: raise lifts the outer ends (and a little of the inner), inner > 0 lifts the inner ends (sad,
  // worried), inner < 0 and a negative raise pull them down and together (angry, focused).
  const raise = mood.browRaise;
  const inner = mood.browInner;
  m.browOuterUpLeft = m.browOuterUpRight = clamp01(raise);
  m.browInnerUp = clamp01(Math.max(0, inner) + Math.max(0, raise) * 0.5);
  m.browDownLeft = m.browDownRight = clamp01(Math.max(0, -inner) * 0.8 + Math.max(0, -raise));
  // Asymmetry (thinking): the avatar's left brow arches up, its right one draws down.
  m.browOuterUpLeft = clamp01(m.browOuterUpLeft + 0.65 * asym);
  m.browOuterUpRight = clamp01(m.browOuterUpRight - 0.5 * asym);
  m.browDownRight = clamp01(m.browDownRight + 0.5 * asym);
  m.browDownLeft = clamp01(m.browDownLeft - 0.4 * asym);

  // Lids: the blink closes them; looking down lowers the upper lids a little; squint narrows, a negative
  // squint (surprise) widens.
  const down = Math.max(0, gaze.eyeY + gaze.pitch * 0.5);
  const closed = clamp01(1 - blink + down * 0.18);
  m.eyeBlinkLeft = m.eyeBlinkRight = closed;
  m.eyeSquintLeft = m.eyeSquintRight = clamp01(mood.squint * 1.6) * (1 - closed);
  m.eyeWideLeft = m.eyeWideRight = clamp01(-mood.squint * 3) * (1 - closed);

  // Idle life: slow breathing and a small drift of the head that never repeats exactly (incommensurate sines).
  const t = nowMs / 1000;
  const drift = {
    yaw: 0.018 * Math.sin(t * 0.53) + 0.009 * Math.sin(t * 1.31 + 1.7),
    pitch: 0.012 * Math.sin(t * 0.71 + 0.4) + 0.006 * Math.sin(t * 1.73 + 2.1),
    roll: 0.01 * Math.sin(t * 0.37 + 0.9),
  };
  const breath = Math.sin((t * 2 * Math.PI) / 4.2);

  return {
    morphs: m,
    // Thinking also glances up and aside, as people do while they search for a word.
    eyes: { yaw: gaze.eyeX * EYE_YAW_RAD + 0.14 * asym, pitch: gaze.eyeY * EYE_PITCH_RAD - 0.12 * asym },
    head: {
      yaw: gaze.yaw * HEAD_YAW_RAD + drift.yaw,
      pitch: gaze.pitch * 0.6 * HEAD_PITCH_RAD + drift.pitch + breath * 0.006,
      // The mood tilts the head (moods.js roll, clockwise on screen, as canvas rotations are); turning leans into it.
      roll: -mood.roll + gaze.yaw * 0.02 + drift.roll,
    },
    breath,
    jaw: mouthOpen(visemes, mood),
  };
}

/** How open the mouth is (0..1) for viseme weights and mood, the 2D face's `jaw` for the same state. */
export function mouthOpen(visemes, mood) {
  let jaw = 0;
  for (const [v, w] of Object.entries(visemes)) jaw += w * mouthShape(v).jaw;
  return Math.min(1, jaw + (visemes.sil ?? 0) * Math.max(0, mood.jaw));
}

/** The viseme with the largest weight. */
export function dominant(visemes) {
  let best = "sil";
  let bw = -1;
  for (const [v, w] of Object.entries(visemes)) {
    if (w > bw) {
      best = v;
      bw = w;
    }
  }
  return best;
}

function clamp01(x) {
  return x < 0 ? 0 : x > 1 ? 1 : x;
}
