//! Microphone capture: getUserMedia -> AudioWorklet (resampled to 22050 Hz, 20 ms s16le chunks) -> a callback.

import { audioContext } from "./audio-context.js";
import { explainMediaError } from "./media-errors.js";

export class Microphone {
  /** `onChunk(Int16Array buffer, rms)` is called for every 20 ms chunk. */
  constructor(onChunk, { echoCancellation }) {
    this.onChunk = onChunk;
    this.echoCancellation = echoCancellation;
    this.stream = null;
    this.node = null;
    this.source = null;
    this.levelDb = -Infinity;
  }

  get running() {
    return this.stream !== null;
  }

  /** Starts capture; throws an Error whose message is meant for the user. */
  async start() {
    if (this.running) return;
    if (!navigator.mediaDevices?.getUserMedia) {
      throw new Error("This page cannot use the microphone here: open it over https or on localhost.");
    }
    let stream;
    try {
      stream = await navigator.mediaDevices.getUserMedia({
        audio: {
          channelCount: 1,
          echoCancellation: this.echoCancellation,
          noiseSuppression: false,
          autoGainControl: false,
        },
      });
    } catch (err) {
      throw new Error(explainMediaError(err, "microphone"));
    }
    const ctx = audioContext();
    await ctx.audioWorklet.addModule(new URL("./capture-worklet.js", import.meta.url));
    this.source = ctx.createMediaStreamSource(stream);
    this.node = new AudioWorkletNode(ctx, "pcm-capture", { numberOfInputs: 1, numberOfOutputs: 0 });
    this.node.port.onmessage = (ev) => {
      const { pcm, rms } = ev.data;
      this.levelDb = rms > 0 ? 20 * Math.log10(rms) : -Infinity;
      this.onChunk(pcm, rms);
    };
    this.source.connect(this.node);
    this.stream = stream;
    for (const track of stream.getAudioTracks()) {
      track.addEventListener("ended", () => this.stop());
    }
  }

  stop() {
    if (!this.stream) return;
    this.source?.disconnect();
    this.node?.port.close();
    this.node?.disconnect();
    for (const t of this.stream.getTracks()) t.stop();
    this.stream = null;
    this.node = null;
    this.source = null;
    this.levelDb = -Infinity;
  }
}
