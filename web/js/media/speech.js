//! Speech playback: PCM chunks from the server played back to back on the WebAudio clock.
//
// Each chunk becomes an AudioBuffer at 22050 Hz (WebAudio resamples to the device rate) scheduled right after the
// previous one, with a 60 ms jitter buffer before the first chunk of an utterance. The audio-clock time of an
// utterance's sample 0 is its anchor: viseme timelines are placed relative to it.

import { audioContext } from "./audio-context.js";

const RATE = 22050;
const JITTER_S = 0.06;
const NEW_UTTERANCE_GAP_S = 0.25; // for unframed PCM (utterance 0): a gap this long starts a new utterance

export class SpeechPlayer {
  /** `onAnchor(utterance, startS)` is called when an utterance's sample 0 gets its audio-clock time. */
  constructor(onAnchor) {
    this.onAnchor = onAnchor;
    this.playhead = 0;
    this.sources = new Set();
    this.anchors = new Map(); // utterance -> audio time of sample 0
    this.current = null;
    this.lastEnd = 0;
    this.chunks = 0;
    /** The gain node speech plays through; replaced after a fade so the next reply starts at full level. */
    this.gain = null;
  }

  /** The node sources connect to: a gain node in front of the destination, for fading out on a barge-in. */
  output(ctx) {
    if (!this.gain) {
      this.gain = ctx.createGain();
      this.gain.connect(ctx.destination);
    }
    return this.gain;
  }

  /** Schedules one chunk of `utterance` starting at sample `offset`. */
  play(utterance, offset, pcm) {
    if (pcm.length === 0) return;
    const ctx = audioContext();
    const now = ctx.currentTime;
    const fresh = this.playhead < now;
    let start = fresh ? now + JITTER_S : this.playhead;
    let anchor = this.anchors.get(utterance);
    const unframedRestart = utterance === 0 && now - this.lastEnd > NEW_UTTERANCE_GAP_S && fresh;
    if (anchor === undefined || unframedRestart) {
      anchor = start - (utterance === 0 ? 0 : offset / RATE);
      this.anchors.set(utterance, anchor);
      this.trimAnchors();
      this.onAnchor(utterance, anchor);
    } else if (utterance !== 0) {
      // A chunk arriving late plays late, but never before its own position in the utterance.
      start = Math.max(start, anchor + offset / RATE);
    }
    const buffer = ctx.createBuffer(1, pcm.length, RATE);
    const data = buffer.getChannelData(0);
    for (let i = 0; i < pcm.length; i++) data[i] = pcm[i] / 32768;
    const src = ctx.createBufferSource();
    src.buffer = buffer;
    src.connect(this.output(ctx));
    src.onended = () => this.sources.delete(src);
    src.start(start);
    this.sources.add(src);
    this.playhead = start + buffer.duration;
    this.lastEnd = this.playhead;
    this.current = utterance;
    this.chunks += 1;
  }

  /** The audio time sample 0 of `utterance` plays at, if it has started. */
  anchorOf(utterance) {
    return this.anchors.get(utterance);
  }

  /**
   * Stops everything: at once, or fading out over `fadeS` seconds (a barge-in: the user is talking, and a fade
   * sounds like yielding where a cut sounds like a fault).
   */
  stop(fadeS = 0) {
    const ctx = this.sources.size > 0 && fadeS > 0 && this.gain ? audioContext() : null;
    const at = ctx ? ctx.currentTime + fadeS : 0;
    if (ctx && this.gain) {
      const g = this.gain.gain;
      g.cancelScheduledValues(ctx.currentTime);
      g.setValueAtTime(g.value, ctx.currentTime);
      g.linearRampToValueAtTime(0, at);
      // The faded node goes with the sources it carries; the next reply gets a fresh one at full level.
      const faded = this.gain;
      this.gain = null;
      setTimeout(() => faded.disconnect(), Math.ceil(fadeS * 1000) + 50);
    }
    for (const s of this.sources) {
      try {
        s.stop(at);
      } catch {
        // Already stopped: nothing to do.
      }
    }
    this.sources.clear();
    this.playhead = 0;
    this.anchors.clear();
  }

  get speaking() {
    return this.sources.size > 0;
  }

  trimAnchors() {
    while (this.anchors.size > 16) {
      const oldest = this.anchors.keys().next().value;
      this.anchors.delete(oldest);
    }
  }
}
