//! AudioWorklet processor: resamples the microphone to 22050 Hz mono (resampler.js) and emits 20 ms s16le chunks.

import { OUT_RATE, Resampler } from "./resampler.js";

const CHUNK = (OUT_RATE * 20) / 1000; // 441 samples: 20 ms at 22050 Hz

class CaptureProcessor extends AudioWorkletProcessor {
  constructor() {
    super();
    // `sampleRate` is the context's rate, a global of the worklet scope.
    this.resampler = new Resampler(sampleRate);
    this.out = new Int16Array(CHUNK);
    this.outLen = 0;
    this.sumSq = 0;
    this.emit = (sample) => this.push(sample);
  }

  process(inputs) {
    const input = inputs[0];
    if (!input || input.length === 0) return true;
    this.resampler.write(input[0], input.length > 1 ? input[1] : null);
    this.resampler.drain(this.emit);
    return true;
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

registerProcessor("pcm-capture", CaptureProcessor);
