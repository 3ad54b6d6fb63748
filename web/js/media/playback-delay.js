// @ts-check
//! The delay a playback route adds, measured by matching the loudness envelope of what the player sends into the
//! route with the envelope of what comes out of it.
//
// Speech played through the loopback peer connection (playback-route.js) is heard later than the audio clock
// says: Opus frames, the receiver's jitter buffer and the audio element's output add tens of milliseconds. Visemes
// are drawn on the audio clock, so the mouth would lead the sound by that much. The player knows the PCM it
// schedules and when; a probe at the far end reports what arrives and when, both on the same audio clock. Each is
// reduced to an envelope (mean magnitude per 5 ms frame), and the lag at which the two envelopes correlate best is
// the delay. A whole stretch of speech is matched, not single onsets: Opus codes noise-like sounds by their
// spectrum rather than their waveform, so the first loud sample of a fricative comes out tens of milliseconds from
// where it went in, while the envelope of a second of speech does not move.
//
// Most of the delay is fixed (frames, the audio element and the probe's input), but the receiver's jitter buffer
// is not: on a busy machine packets arrive unevenly and WebRTC grows the buffer, by over a hundred milliseconds in
// the middle of an utterance, which a median of two-second matches follows only seconds later. The receiver
// reports its buffer's delay (`getStats`, a few times a second), so each match is kept as the part the buffer does
// not explain (the match less the buffer's mean delay over the stretch), and the delay now is the median of those
// parts plus the buffer's delay now. A measurement never corrects the schedule it was measured on: the matches
// only give the fixed part, and what moves comes from the receiver's own figure.

/** Length of one envelope frame (seconds). */
export const FRAME_S = 0.005;
/** The stretch of envelope matched at a time (frames): two seconds, several words. */
export const MATCH_FRAMES = 400;
/** The longest delay looked for (frames): 500 ms, room for a jitter buffer held long (`?playbackbuffer=`). */
export const MAX_LAG_FRAMES = 100;
/** The correlation a match needs to count: speech against its own delayed copy is far above it, noise far below. */
export const MIN_SCORE = 0.8;
/** The mean magnitude a frame needs to count as sound (of full scale; speech is well above it). */
const SOUND_LEVEL = 0.01;
/** Envelope frames kept (frames): enough for a match window and the longest lag, with room to spare. */
const KEEP_FRAMES = 1024;
/** Measurements kept; the estimate is their median, so one odd stretch does not move it far. */
const KEEP = 7;
/** Jitter-buffer readings kept (one every quarter second: half a minute). */
const KEEP_JITTER = 120;

/** Mean magnitude per `FRAME_S` frame of a signal on the audio clock, for the last `KEEP_FRAMES` frames. */
export class EnvelopeTrack {
  constructor() {
    this.sums = new Float64Array(KEEP_FRAMES);
    this.counts = new Uint32Array(KEEP_FRAMES);
    /** The frame index each slot holds (a slot is reused once its frame is KEEP_FRAMES old). */
    this.index = new Float64Array(KEEP_FRAMES).fill(-1);
    this.last = -1;
  }

  /**
   * Adds `block`, sampled at `rate`, whose first sample plays at audio time `startS`.
   * @param {Float32Array | number[]} block
   * @param {number} startS
   * @param {number} rate
   */
  add(block, startS, rate) {
    for (let i = 0; i < block.length; i++) {
      const frame = Math.floor((startS + i / rate) / FRAME_S);
      const slot = frame % KEEP_FRAMES;
      if (this.index[slot] !== frame) {
        this.index[slot] = frame;
        this.sums[slot] = 0;
        this.counts[slot] = 0;
      }
      this.sums[slot] += Math.abs(block[i]);
      this.counts[slot] += 1;
      if (frame > this.last) this.last = frame;
    }
  }

  /**
   * Adds whole frames from `first` on (what the probe worklet posts).
   * @param {number} first
   * @param {Float32Array | number[]} values
   */
  addFrames(first, values) {
    for (let k = 0; k < values.length; k++) {
      const frame = first + k;
      const slot = frame % KEEP_FRAMES;
      this.index[slot] = frame;
      this.sums[slot] = values[k];
      this.counts[slot] = 1;
      if (frame > this.last) this.last = frame;
    }
  }

  /**
   * The envelope of frames `from` .. `from + n - 1`; frames never seen (silence, or too old) are 0.
   * @param {number} from
   * @param {number} n
   */
  frames(from, n) {
    const out = new Float32Array(n);
    for (let k = 0; k < n; k++) {
      const frame = from + k;
      const slot = ((frame % KEEP_FRAMES) + KEEP_FRAMES) % KEEP_FRAMES;
      if (frame >= 0 && this.index[slot] === frame && this.counts[slot] > 0) out[k] = this.sums[slot] / this.counts[slot];
    }
    return out;
  }
}

/**
 * The lag (in frames, fractional) at which `received` best matches `sent` delayed, and how well (Pearson
 * correlation), or null when either stretch is too flat to tell (silence). `sent` must start `maxLag` frames
 * before `received` and be `maxLag` frames longer: `received[i]` is compared with `sent[i + maxLag - lag]`.
 * @param {Float32Array} sent
 * @param {Float32Array} received
 * @param {number} maxLag
 * @returns {{lag: number, score: number} | null}
 */
export function bestLag(sent, received, maxLag) {
  const n = received.length;
  if (sent.length !== n + maxLag || n < 2) return null;
  const r = stats(received, 0, n);
  if (r.sd < 1e-4) return null;
  const scores = new Float64Array(maxLag + 1);
  let best = -1;
  for (let lag = 0; lag <= maxLag; lag++) {
    const off = maxLag - lag;
    const s = stats(sent, off, n);
    if (s.sd < 1e-4) {
      scores[lag] = -1;
      continue;
    }
    let cov = 0;
    for (let i = 0; i < n; i++) cov += (received[i] - r.mean) * (sent[off + i] - s.mean);
    scores[lag] = cov / (n * r.sd * s.sd);
    if (best < 0 || scores[lag] > scores[best]) best = lag;
  }
  if (best < 0) return null;
  // A parabola through the peak and its neighbours places it between frames.
  let lag = best;
  if (best > 0 && best < maxLag) {
    const [a, b, c] = [scores[best - 1], scores[best], scores[best + 1]];
    const denom = a - 2 * b + c;
    if (denom < 0) lag = best + (0.5 * (a - c)) / denom;
  }
  return { lag, score: scores[best] };
}

/**
 * @param {Float32Array} v
 * @param {number} from
 * @param {number} n
 */
function stats(v, from, n) {
  let sum = 0;
  for (let i = 0; i < n; i++) sum += v[from + i];
  const mean = sum / n;
  let sq = 0;
  for (let i = 0; i < n; i++) sq += (v[from + i] - mean) ** 2;
  return { mean, sd: Math.sqrt(sq / n) };
}

/** The receiver's jitter-buffer delay over time: readings on the audio clock, each the mean since the last. */
export class JitterTrack {
  constructor() {
    /** @type {{atS: number, delayS: number}[]} */
    this.readings = [];
  }

  /**
   * Adds the buffer's mean delay over the samples it let out since the last reading, read at audio time `atS`.
   * @param {number} atS
   * @param {number} delayS
   */
  add(atS, delayS) {
    if (!Number.isFinite(atS) || !Number.isFinite(delayS) || delayS < 0) return;
    this.readings.push({ atS, delayS });
    if (this.readings.length > KEEP_JITTER) this.readings.shift();
  }

  /** The latest reading (seconds), or null before any. */
  get latestS() {
    const last = this.readings[this.readings.length - 1];
    return last ? last.delayS : null;
  }

  /**
   * The mean delay over audio times `fromS` .. `toS`: the readings taken in it and the first one after (which covers
   * the end of it), or null when none covers it.
   * @param {number} fromS
   * @param {number} toS
   */
  meanOver(fromS, toS) {
    let sum = 0;
    let n = 0;
    for (const r of this.readings) {
      if (r.atS < fromS) continue;
      sum += r.delayS;
      n += 1;
      if (r.atS > toS) break;
    }
    return n > 0 ? sum / n : null;
  }
}

/** The route's delay: recent envelope matches, less the jitter buffer they held, plus the buffer's delay now. */
export class DelayEstimator {
  /**
   * @param {number} initialS the estimate before anything is measured and without a jitter-buffer reading
   * @param {number | null} fixedGuessS the part of the delay the jitter buffer does not explain, assumed before
   *   anything is measured (the estimate is then this plus the buffer's latest reading)
   */
  constructor(initialS, fixedGuessS = null) {
    this.initialS = initialS;
    this.fixedGuessS = fixedGuessS;
    this.sent = new EnvelopeTrack();
    this.received = new EnvelopeTrack();
    this.jitter = new JitterTrack();
    /** @type {number[]} the delays matched */
    this.measured = [];
    /** @type {(number | null)[]} for each match, the part the jitter buffer does not explain (null: no reading) */
    this.fixed = [];
    this.lastMatched = -Infinity;
  }

  /**
   * Matches the last `MATCH_FRAMES` frames received, up to frame `upTo`, against what was sent; returns the delay
   * found (seconds), the match's score and the receiver's jitter buffer over the stretch (seconds, null without a
   * reading), or null when the stretch holds no speech to match, or it matched too
   * poorly. A stretch is matched once: the next match needs a stretch that has moved on by half its length.
   * @param {number} upTo
   * @returns {{delayS: number, score: number, bufferedS: number | null} | null}
   */
  match(upTo) {
    if (upTo - this.lastMatched < MATCH_FRAMES / 2) return null;
    const from = upTo - MATCH_FRAMES + 1;
    const received = this.received.frames(from, MATCH_FRAMES);
    // Mostly silence with one edge of speech in it matches at almost any lag: a stretch must be a quarter sound.
    let loud = 0;
    for (const v of received) if (v > SOUND_LEVEL) loud += 1;
    if (loud < MATCH_FRAMES / 4) return null;
    const found = bestLag(
      this.sent.frames(from - MAX_LAG_FRAMES, MATCH_FRAMES + MAX_LAG_FRAMES),
      received,
      MAX_LAG_FRAMES,
    );
    if (!found || found.score < MIN_SCORE) return null;
    this.lastMatched = upTo;
    const delayS = found.lag * FRAME_S;
    const buffered = this.jitter.meanOver(from * FRAME_S, (upTo + 1) * FRAME_S);
    this.measured.push(delayS);
    this.fixed.push(buffered === null ? null : delayS - buffered);
    if (this.measured.length > KEEP) {
      this.measured.shift();
      this.fixed.shift();
    }
    return { delayS, score: found.score, bufferedS: buffered };
  }

  /**
   * The delay to compensate now (seconds): the median fixed part (of the matches made with a buffer reading) plus
   * the jitter buffer's latest reading; the median of the matches themselves where the receiver gives no readings;
   * before any match, the guessed fixed part plus the buffer's reading, or the initial guess.
   */
  get delayS() {
    const now = this.jitter.latestS;
    if (this.measured.length === 0) {
      return this.fixedGuessS !== null && now !== null ? this.fixedGuessS + now : this.initialS;
    }
    const fixed = /** @type {number[]} */ (this.fixed.filter((f) => f !== null));
    if (now !== null && fixed.length > 0) return Math.max(0, median(fixed) + now);
    return median(this.measured);
  }
}

/** @param {number[]} values (not empty) */
function median(values) {
  const s = [...values].sort((a, b) => a - b);
  const mid = s.length >> 1;
  return s.length % 2 ? s[mid] : (s[mid - 1] + s[mid]) / 2;
}

/**
 * While speech plays, the heard clock's shift follows the route's delay at most this fast (seconds per second of
 * audio), so the heard clock never runs backwards: the mouth slows down while the receiver stretches the sound to
 * fill a growing jitter buffer, as the sound does, instead of jumping back.
 */
export const SHIFT_SLEW = 0.5;
/** Shifts in effect kept, for pairing them with the route's measurements. */
const KEEP_SHIFTS = 600;

/**
 * How far behind the audio clock the sound is heard, as the clock visemes are drawn on uses it: the route's delay,
 * taken at once while nothing plays and followed at most `SHIFT_SLEW` as fast as the clock while speech plays.
 */
export class HeardShift {
  constructor() {
    this.s = 0;
    this.atS = -Infinity;
    /** @type {{atS: number, shiftS: number}[]} the shift in effect from each audio time on */
    this.history = [];
  }

  /**
   * The shift at audio time `nowS`, moved towards the route's delay `targetS`.
   * @param {number} nowS
   * @param {number} targetS
   * @param {boolean} playing speech is being heard, so the shift may not jump
   */
  follow(nowS, targetS, playing) {
    // A clock that went back is another clock: the page draws on its own clock until the audio context exists,
    // whose clock then starts from 0. Shifts recorded on the first would hide those of the second from `at`
    // (CI's playback test saw a first stretch reported with no shift, though it was drawn with the right one).
    if (nowS < this.atS) {
      this.history = [];
      this.atS = -Infinity;
    }
    const elapsed = nowS - this.atS;
    let s = targetS;
    if (playing && Number.isFinite(elapsed) && elapsed >= 0) {
      const step = elapsed * SHIFT_SLEW;
      s = this.s + Math.max(-step, Math.min(step, targetS - this.s));
    }
    if (s !== this.s || this.history.length === 0) {
      this.history.push({ atS: nowS, shiftS: s });
      if (this.history.length > KEEP_SHIFTS) this.history.shift();
    }
    this.s = s;
    this.atS = nowS;
    return s;
  }

  /**
   * The shift in effect at audio time `atS`.
   * @param {number} atS
   */
  at(atS) {
    let s = this.history.length > 0 ? this.history[0].shiftS : this.s;
    for (const e of this.history) {
      if (e.atS > atS) break;
      s = e.shiftS;
    }
    return s;
  }
}
