//! AudioWorklet processor: the loudness envelope (mean magnitude per 5 ms frame, on the audio clock) of what the
//! loopback playback route delivers, posted every 100 ms, so that the page can measure the delay the route adds
//! (playback-delay.js).

import { FRAME_S } from "./playback-delay.js";

const POST_FRAMES = 20; // 100 ms

class EnvelopeProbe extends AudioWorkletProcessor {
  constructor() {
    super();
    this.frame = -1; // the frame being summed
    this.sum = 0;
    this.count = 0;
    this.first = -1; // the first frame of the batch being gathered
    this.values = [];
  }

  process(inputs) {
    const input = inputs[0];
    if (!input || input.length === 0) return true;
    const samples = input[0];
    // `currentTime` and `sampleRate` are globals of the worklet scope: the audio time of this block's first sample
    // and the context's rate.
    for (let i = 0; i < samples.length; i++) {
      const frame = Math.floor((currentTime + i / sampleRate) / FRAME_S);
      if (frame !== this.frame) {
        if (this.count > 0) this.close();
        this.frame = frame;
        this.sum = 0;
        this.count = 0;
      }
      this.sum += Math.abs(samples[i]);
      this.count += 1;
    }
    return true;
  }

  /** The frame being summed is complete: it joins the batch, which is posted once full or broken by a gap. */
  close() {
    if (this.values.length > 0 && this.frame !== this.first + this.values.length) this.flush();
    if (this.values.length === 0) this.first = this.frame;
    this.values.push(this.sum / this.count);
    if (this.values.length >= POST_FRAMES) this.flush();
  }

  flush() {
    if (this.values.length > 0) this.port.postMessage({ first: this.first, values: Float32Array.from(this.values) });
    this.values = [];
  }
}

registerProcessor("envelope-probe", EnvelopeProbe);
