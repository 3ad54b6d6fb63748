//! Speech playback: PCM chunks from the server played back to back on the WebAudio clock.
//
// Each chunk becomes an AudioBuffer at 22050 Hz (WebAudio resamples to the device rate) scheduled right after the
// previous one, with a 60 ms jitter buffer before the first chunk of an utterance. The audio-clock time of an
// utterance's sample 0 is its anchor. What leaves the player goes through a playback route (playback-route.js):
// the loopback one, which the echo canceller covers, is heard later than the audio clock says, by a delay that
// moves when its jitter buffer does, so visemes are placed at the anchor on the audio clock and drawn on the heard
// clock (`heardClock`): the audio clock less the route's delay at that moment.

import { audioContext } from "./audio-context.js";
import { HeardShift } from "./playback-delay.js";
import { DirectRoute } from "./playback-route.js";

const RATE = 22050;
const JITTER_S = 0.06;
const NEW_UTTERANCE_GAP_S = 0.25; // for unframed PCM (utterance 0): a gap this long starts a new utterance


export class SpeechPlayer {
  /**
   * `onAnchor(utterance, atS)` is called when an utterance's sample 0 gets its audio-clock time, the time visemes
   * are placed from (and drawn on `heardClock`).
   */
  constructor(onAnchor) {
    this.onAnchor = onAnchor;
    this.playhead = 0;
    this.sources = new Set();
    // utterance -> {at}: the audio time its sample 0 enters the route.
    this.anchors = new Map();
    /** How far behind the audio clock the sound is heard (playback-delay.js). */
    this.shift = new HeardShift();
    /**
     * Until this audio time nothing scheduled is heard yet (a fresh start is scheduled ahead, and the route delays
     * it): the shift may jump. From then on until the last chunk's end is heard, it may not.
     */
    this.quietUntil = -Infinity;
    /** @type {DirectRoute | import("./playback-route.js").LoopbackRoute | null} */
    this.route = null;
    this.nextRoute = null;
    this.routeError = null;
    this.current = null;
    this.lastEnd = 0;
    this.chunks = 0;
    /** The gain node speech plays through; replaced after a fade so the next reply starts at full level. */
    this.gain = null;
  }

  /** The node sources connect to: a gain node in front of the destination, for fading out on a barge-in. */
  output(ctx) {
    if (!this.route) this.route = new DirectRoute(ctx);
    if (!this.gain) {
      this.gain = ctx.createGain();
      this.gain.connect(this.route.input);
    }
    return this.gain;
  }

  /**
   * Plays through `route` from the next utterance on: switching in the middle of one would make the rest of it
   * heard a route's delay later, a jump its visemes would make at a different moment.
   */
  useRoute(route) {
    route.tagAt = (sentS, heardS) => {
      const tag = this.tagAt(sentS);
      return tag ? { ...tag, appliedS: this.shift.at(heardS) } : null;
    };
    this.nextRoute = route;
    if (!this.speaking) this.switchRoute();
  }

  switchRoute() {
    if (!this.nextRoute) return;
    this.route = this.nextRoute;
    this.nextRoute = null;
    if (this.gain) {
      this.gain.disconnect();
      this.gain.connect(this.route.input);
    }
  }

  /** The playback route's state for the debug hook: which route, its delay and the measurements behind it. */
  routeState() {
    const state = this.route ? this.route.debugState() : DirectRoute.idleState();
    return { ...state, error: this.routeError };
  }

  /** Schedules one chunk of `utterance` starting at sample `offset`. */
  play(utterance, offset, pcm) {
    if (pcm.length === 0) return;
    const ctx = audioContext();
    const now = ctx.currentTime;
    // A context that has not started yet reads 0, as the playhead does before any speech: that first chunk is a
    // fresh start too.
    const fresh = this.playhead <= now;
    if (fresh) {
      this.switchRoute();
      // The shift takes the route's delay at once while nothing is heard. Drawing follows it too (heardTime), but
      // an idle page draws no frames: without this, the first utterance through a route opened while the page was
      // at rest started at the shift of the route before (0) and slewed towards the right one while it was heard
      // (tests/playback.rs saw the first stretch's visemes 80 ms ahead of the sound).
      if (now >= this.lastEnd + this.shift.s) this.shift.follow(now, this.routeDelayS, false);
      this.quietUntil = now + JITTER_S + this.shift.s;
    }
    const ctxOut = this.output(ctx);
    let start = fresh ? now + JITTER_S : this.playhead;
    let anchor = this.anchors.get(utterance)?.at;
    const unframedRestart = utterance === 0 && now - this.lastEnd > NEW_UTTERANCE_GAP_S && fresh;
    if (anchor === undefined || unframedRestart) {
      anchor = start - (utterance === 0 ? 0 : offset / RATE);
      this.anchors.set(utterance, { at: anchor });
      this.trimAnchors();
      this.onAnchor(utterance, this.anchorOf(utterance));
    } else if (utterance !== 0) {
      // A chunk arriving late plays late, but never before its own position in the utterance.
      start = Math.max(start, anchor + offset / RATE);
    }
    const buffer = ctx.createBuffer(1, pcm.length, RATE);
    const data = buffer.getChannelData(0);
    for (let i = 0; i < pcm.length; i++) data[i] = pcm[i] / 32768;
    // The route matches what it was sent against what comes out of it.
    this.route?.sent(data, start, RATE);
    const src = ctx.createBufferSource();
    src.buffer = buffer;
    src.connect(ctxOut);
    src.onended = () => this.sources.delete(src);
    src.start(start);
    this.sources.add(src);
    this.playhead = start + buffer.duration;
    this.lastEnd = this.playhead;
    this.current = utterance;
    this.chunks += 1;
  }

  /** The utterance sent at audio time `atS` (the latest to start before it). */
  tagAt(atS) {
    let found = null;
    for (const [utterance, a] of this.anchors) {
      if (a.at <= atS && (!found || a.at > found.at)) found = { utterance, at: a.at };
    }
    return found ? { utterance: found.utterance } : null;
  }

  /** The audio time sample 0 of `utterance` enters the route at (its anchor), if it has started. */
  anchorOf(utterance) {
    return this.anchors.get(utterance)?.at;
  }

  /** How far behind the audio clock the sound is heard now (seconds): the route's delay, 0 before any route. */
  get routeDelayS() {
    return this.route ? this.route.delayS : 0;
  }

  /**
   * The audio time being heard at audio time `nowS`: `nowS` less the route's delay, which the shift takes at once
   * before an utterance is heard and follows gradually while one plays.
   * @param {number} nowS
   */
  heardTime(nowS) {
    // Sound is heard from a fresh start's first sample to the last chunk's end, each a shift after the audio clock
    // has it: the route still plays the tail of a reply after its last source has ended.
    const hearing = nowS >= this.quietUntil && nowS < this.lastEnd + this.shift.s;
    return nowS - this.shift.follow(nowS, this.routeDelayS, hearing);
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
