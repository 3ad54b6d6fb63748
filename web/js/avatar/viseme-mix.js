// @ts-check
//! Co-articulated visemes on the audio clock: how much of each mouth shape is on at a given audio time.
//
// Each cue blends into the next over a short transition that starts a little before the cue (the mouth
// anticipates the next sound, as it does in speech) and ends at most `LAG_S` after it. The weights are a pure
// function of the audio time, so the mouth follows the sound WebAudio plays whatever the frame rate, and a page
// that draws at 30 fps shows the same mouth at the same instant as one that draws at 60.

const TRANSITION_S = 0.06; // a cue's blend-in, shortened when cues come faster
const LEAD = 1 / 3; // share of the blend before the cue's time
export const LAG_S = TRANSITION_S * (1 - LEAD); // the shape is fully on this long after its cue
const TRAILING_S = 0.12; // as in viseme-track.js: the last cue holds briefly, then the mouth rests

/** @typedef {{ at: number, v: string, utterance: number }} Cue */

export class VisemeMixer {
  constructor() {
    /** @type {Cue[]} */
    this.cues = [];
  }

  /** Adds `items` ([{t_ms, v}]) of `utterance` whose sample 0 plays at audio time `startS`. */
  add(utterance, startS, items) {
    for (const it of items) {
      if (!it || typeof it.v !== "string" || !Number.isFinite(it.t_ms)) continue;
      this.cues.push({ at: startS + it.t_ms / 1000, v: it.v, utterance });
    }
    this.cues.sort((a, b) => a.at - b.at);
  }

  /** Drops everything (barge-in), or only `utterance`'s cues. */
  clear(utterance) {
    this.cues = utterance === undefined ? [] : this.cues.filter((c) => c.utterance !== utterance);
  }

  /** The cues as steps: [{at, v}] with the trailing rest appended after the last cue. */
  steps() {
    const out = this.cues.map((c) => ({ at: c.at, v: c.v }));
    const last = out[out.length - 1];
    if (last && last.v !== "sil") out.push({ at: last.at + TRAILING_S, v: "sil" });
    return out;
  }

  /**
   * The weight of each viseme at audio time `nowS` ({name: weight}, summing to 1; {sil: 1} at rest). Cues long
   * past are forgotten.
   */
  weights(nowS) {
    const steps = this.steps();
    /** @type {Record<string, number>} */
    const w = { sil: 1 };
    if (steps.length === 0) return w;
    // The step whose blend is under way or done at nowS: the latest whose blend has started.
    let i = -1;
    for (let k = 0; k < steps.length; k++) {
      if (steps[k].at - blendOf(steps, k) * LEAD <= nowS) i = k;
      else break;
    }
    if (i < 0) return w;
    const cur = steps[i];
    const prev = i > 0 ? steps[i - 1].v : "sil";
    const d = blendOf(steps, i);
    const k = d <= 0 ? 1 : clamp01((nowS - (cur.at - d * LEAD)) / d);
    const e = k * k * (3 - 2 * k);
    /** @type {Record<string, number>} */
    const out = {};
    out[prev] = (out[prev] ?? 0) + (1 - e);
    out[cur.v] = (out[cur.v] ?? 0) + e;
    // Forget cues that can no longer matter: everything before the previous one, once the last has rested.
    if (i === steps.length - 1 && e >= 1) this.cues = [];
    else if (i > 1) {
      const keepFrom = steps[i - 1].at;
      this.cues = this.cues.filter((c) => c.at >= keepFrom);
    }
    return out;
  }

  get pending() {
    return this.cues.length;
  }
}

/** The blend length into step `k`: at most TRANSITION_S, and no more than half the gap to its neighbours. */
function blendOf(steps, k) {
  let d = TRANSITION_S;
  if (k > 0) d = Math.min(d, (steps[k].at - steps[k - 1].at) * 0.9);
  return Math.max(0, d);
}

function clamp01(x) {
  return x < 0 ? 0 : x > 1 ? 1 : x;
}
