// @ts-check
//! Windowed-sinc resampling of the microphone to the link's 22050 Hz: pure, so that the capture worklet runs it on
//! the audio thread and `node --test` checks it (web/test/resampler.test.mjs).
//
// A plain linear interpolation would fold everything above 11 kHz back into the band Whisper listens to, so the
// input is low-passed by a Blackman-windowed sinc, tabulated once so the audio thread only multiplies and adds.

export const OUT_RATE = 22050;
const ZERO_CROSSINGS = 12; // filter half-length in output periods
const TABLE_STEPS = 256; // sub-sample positions tabulated per input sample

export class Resampler {
  /**
   * @param {number} inRate the input rate (the audio context's, 44.1 or 48 kHz usually)
   * @param {number} outRate the output rate
   */
  constructor(inRate, outRate = OUT_RATE) {
    this.step = inRate / outRate; // input samples per output sample
    const cutoff = Math.min(1, 1 / this.step) * 0.92; // relative to the input Nyquist
    this.half = Math.ceil(ZERO_CROSSINGS / cutoff); // taps on each side, in input samples
    this.table = buildTable(this.half, cutoff);
    this.buf = new Float32Array(8192);
    this.len = 0;
    this.pos = this.half; // fractional input index of the next output sample
  }

  /**
   * Appends input: one channel, or two mixed to mono.
   * @param {Float32Array} left
   * @param {Float32Array | null} [right]
   */
  write(left, right = null) {
    if (this.len + left.length > this.buf.length) {
      const bigger = new Float32Array(Math.max(this.buf.length * 2, this.len + left.length));
      bigger.set(this.buf.subarray(0, this.len));
      this.buf = bigger;
    }
    for (let i = 0; i < left.length; i++) {
      this.buf[this.len + i] = right ? 0.5 * (left[i] + right[i]) : left[i];
    }
    this.len += left.length;
  }

  /**
   * Calls `emit` with every output sample the input written so far allows, in order.
   * @param {(sample: number) => void} emit
   */
  drain(emit) {
    const { buf, half, table } = this;
    while (this.pos + half < this.len) {
      const base = Math.floor(this.pos);
      const frac = this.pos - base;
      let acc = 0;
      for (let k = -half + 1; k <= half; k++) {
        // Distance from the output instant to input sample base+k, looked up in the table.
        const d = Math.abs(k - frac) * TABLE_STEPS;
        const i = Math.floor(d);
        const w = i + 1 < table.length ? table[i] + (table[i + 1] - table[i]) * (d - i) : 0;
        acc += buf[base + k] * w;
      }
      emit(acc);
      this.pos += this.step;
    }
    // Drop input that no future output sample will reach.
    const keepFrom = Math.max(0, Math.floor(this.pos) - half);
    if (keepFrom > 0) {
      buf.copyWithin(0, keepFrom, this.len);
      this.len -= keepFrom;
      this.pos -= keepFrom;
    }
  }
}

/**
 * Blackman-windowed sinc low-pass with `cutoff` (fraction of the input Nyquist), tabulated over |distance|.
 * @param {number} half
 * @param {number} cutoff
 */
function buildTable(half, cutoff) {
  const n = half * TABLE_STEPS + 2;
  const t = new Float32Array(n);
  for (let i = 0; i < n; i++) {
    const x = i / TABLE_STEPS;
    if (x >= half) {
      t[i] = 0;
      continue;
    }
    const sinc = x === 0 ? 1 : Math.sin(Math.PI * cutoff * x) / (Math.PI * cutoff * x);
    const r = x / half; // 0..1 from the centre to the edge of the window
    const win = 0.42 + 0.5 * Math.cos(Math.PI * r) + 0.08 * Math.cos(2 * Math.PI * r);
    t[i] = cutoff * sinc * win;
  }
  return t;
}
