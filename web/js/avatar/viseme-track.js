// @ts-check
//! A timeline of visemes on the audio clock: which mouth shape is due at a given audio time.
//
// Items are stored with absolute audio-clock times (seconds), so lips follow the sound that WebAudio actually
// plays, whatever delays the network added to either the PCM or the viseme message.

const TRAILING_S = 0.12; // the last viseme holds briefly, then the mouth returns to rest

export class VisemeTrack {
  constructor() {
    this.items = []; // {at, v, utterance}
  }

  /** Adds `items` ([{t_ms, v}]) of `utterance` whose sample 0 plays at audio time `startS`. */
  add(utterance, startS, items) {
    for (const it of items) {
      if (!it || typeof it.v !== "string" || !Number.isFinite(it.t_ms)) continue;
      this.items.push({ at: startS + it.t_ms / 1000, v: it.v, utterance });
    }
    this.items.sort((a, b) => a.at - b.at);
  }

  /** Drops everything (barge-in), or only `utterance`'s items. */
  clear(utterance) {
    this.items = utterance === undefined ? [] : this.items.filter((i) => i.utterance !== utterance);
  }

  /** The viseme due at audio time `nowS` ("sil" when none), forgetting items that are long past. */
  at(nowS) {
    let current = "sil";
    let idx = -1;
    for (let i = 0; i < this.items.length; i++) {
      if (this.items[i].at <= nowS) idx = i;
      else break;
    }
    if (idx >= 0) {
      const last = idx === this.items.length - 1;
      current = last && nowS - this.items[idx].at > TRAILING_S ? "sil" : this.items[idx].v;
      // Keep the item that is active now; older ones will never be needed again.
      if (idx > 0) this.items.splice(0, idx);
      if (last && current === "sil") this.items = [];
    }
    return current;
  }

  get pending() {
    return this.items.length;
  }
}
