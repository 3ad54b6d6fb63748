//! AudioWorklet processor: resamples the microphone to 22050 Hz mono and emits 20 ms s16le chunks.
//
// The context runs at the device rate (44.1 or 48 kHz usually), so the worklet resamples with a windowed-sinc
// low-pass interpolator; a plain linear interpolation would fold everything above 11 kHz back into the band
// Whisper listens to. The filter is tabulated once so the audio thread only multiplies and adds.

const OUT_RATE = 22050;
const CHUNK = 441; // 20 ms at 22050 Hz
const ZERO_CROSSINGS = 12; // filter half-length in output periods
const TABLE_STEPS = 256; // sub-sample positions tabulated per input sample

class CaptureProcessor extends AudioWorkletProcessor {
  constructor() {
    super();
    // `sampleRate` is the context's rate, a global of the worklet scope.
    this.step = sampleRate / OUT_RATE; // input samples per output sample
    const cutoff = Math.min(1, 1 / this.step) * 0.92; // relative to the input Nyquist
    this.half = Math.ceil(ZERO_CROSSINGS / cutoff); // taps on each side, in input samples
    this.table = buildTable(this.half, cutoff);
    this.buf = new Float32Array(8192);
    this.len = 0;
    this.pos = this.half; // fractional input index of the next output sample
    this.out = new Int16Array(CHUNK);
    this.outLen = 0;
    this.sumSq = 0;
  }

  process(inputs) {
    const input = inputs[0];
    if (!input || input.length === 0) return true;
    const ch = input[0];
    this.append(ch, input.length > 1 ? input[1] : null);
    this.resample();
    return true;
  }

  append(left, right) {
    if (this.len + left.length > this.buf.length) {
      const bigger = new Float32Array(this.buf.length * 2);
      bigger.set(this.buf.subarray(0, this.len));
      this.buf = bigger;
    }
    for (let i = 0; i < left.length; i++) {
      this.buf[this.len + i] = right ? 0.5 * (left[i] + right[i]) : left[i];
    }
    this.len += left.length;
  }

  resample() {
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
      this.push(acc);
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

  push(sample) {
    const s = Math.max(-1, Math.min(1, sample));
    this.out[this.outLen++] = s < 0 ? Math.round(s * 32768) : Math.round(s * 32767);
    this.sumSq += s * s;
    if (this.outLen === CHUNK) {
      const chunk = this.out.buffer;
      const rms = Math.sqrt(this.sumSq / CHUNK);
      this.port.postMessage({ pcm: chunk, rms }, [chunk]);
      this.out = new Int16Array(CHUNK);
      this.outLen = 0;
      this.sumSq = 0;
    }
  }
}

/** Blackman-windowed sinc low-pass with `cutoff` (fraction of the input Nyquist), tabulated over |distance|. */
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

registerProcessor("pcm-capture", CaptureProcessor);
