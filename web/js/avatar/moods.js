// @ts-check
//! Facial expressions for the `mood` command: how brows, lids, mouth corners and head tilt change per mood.

// `asym` (3D head only; the 2D face ignores it): one brow up and the other down, one mouth corner drawn in, the
// lopsided look of someone weighing something up.
const MOODS = {
  neutral: { browRaise: 0, browInner: 0, smile: 0.15, squint: 0, blush: 0.25, roll: 0, jaw: 0, asym: 0 },
  happy: { browRaise: 0.25, browInner: 0.1, smile: 1.0, squint: 0.18, blush: 0.7, roll: 0.03, jaw: 0.06, asym: 0 },
  sad: { browRaise: -0.1, browInner: 0.9, smile: -0.7, squint: 0.2, blush: 0.1, roll: -0.04, jaw: 0, asym: 0 },
  surprised: { browRaise: 1.0, browInner: 0.3, smile: 0, squint: -0.15, blush: 0.3, roll: 0, jaw: 0.35, asym: 0 },
  angry: { browRaise: -0.4, browInner: -1.0, smile: -0.5, squint: 0.3, blush: 0.45, roll: 0, jaw: 0, asym: 0 },
  thinking: { browRaise: 0.35, browInner: -0.3, smile: -0.1, squint: 0.12, blush: 0.2, roll: 0.06, jaw: 0, asym: 1 },
  listening: { browRaise: 0.3, browInner: 0.2, smile: 0.3, squint: 0, blush: 0.3, roll: -0.05, jaw: 0, asym: 0 },
};

export const MOOD_NAMES = Object.freeze(Object.keys(MOODS));

/** The expression for `name` blended from neutral by `intensity` (0..1); unknown names give neutral. */
export function expression(name, intensity = 1) {
  const base = MOODS.neutral;
  const target = MOODS[name] ?? base;
  const k = Math.max(0, Math.min(1, intensity));
  const out = {};
  for (const key of Object.keys(base)) {
    out[key] = base[key] + (target[key] - base[key]) * k;
  }
  return out;
}
