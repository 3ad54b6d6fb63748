//! Camera capture: getUserMedia -> preview <video> -> 640x360 JPEG frames at an adjustable frame rate.
//
// Frames are scaled to cover 640x360 (centre crop, like the preview's object-fit: cover), so the detection
// coordinates the server sends line up with the preview. A frame is skipped, not queued, while the previous one is
// still being encoded or while the socket has a backlog: the counter `skipped` shows it in the status strip.

import { explainMediaError } from "./media-errors.js";

export const FRAME_WIDTH = 640;
export const FRAME_HEIGHT = 360;
const JPEG_QUALITY = 0.75;

export class Camera {
  /** `onFrame(ArrayBuffer jpeg)` is called per frame; `canSend()` says whether the link can take one now. */
  constructor(video, onFrame, canSend) {
    this.video = video;
    this.onFrame = onFrame;
    this.canSend = canSend;
    this.stream = null;
    this.fps = 15;
    this.canvas = document.createElement("canvas");
    this.canvas.width = FRAME_WIDTH;
    this.canvas.height = FRAME_HEIGHT;
    this.ctx = this.canvas.getContext("2d", { alpha: false });
    this.timer = null;
    this.encoding = false;
    this.skipped = 0;
    this.nextAt = 0;
  }

  get running() {
    return this.stream !== null;
  }

  async start() {
    if (this.running) return;
    if (!navigator.mediaDevices?.getUserMedia) {
      throw new Error("This page cannot use the camera here: open it over https or on localhost.");
    }
    let stream;
    try {
      stream = await navigator.mediaDevices.getUserMedia({
        video: { width: { ideal: FRAME_WIDTH }, height: { ideal: FRAME_HEIGHT }, frameRate: { ideal: 15 } },
      });
    } catch (err) {
      throw new Error(explainMediaError(err, "camera"));
    }
    this.stream = stream;
    this.video.srcObject = stream;
    await this.video.play().catch(() => {});
    for (const track of stream.getVideoTracks()) {
      track.addEventListener("ended", () => this.stop());
    }
    this.nextAt = performance.now();
    this.tick();
  }

  /** Changes the capture rate (the server's advice, 5..15 fps). */
  setFps(fps) {
    if (Number.isFinite(fps)) this.fps = Math.max(1, Math.min(15, fps));
  }

  tick() {
    if (!this.running) return;
    const now = performance.now();
    const interval = 1000 / this.fps;
    // Keep a steady cadence: schedule from the ideal time, not from when the timer happened to fire.
    this.nextAt = Math.max(this.nextAt + interval, now + 1);
    this.timer = setTimeout(() => this.tick(), this.nextAt - now);
    this.capture();
  }

  capture() {
    const v = this.video;
    if (v.readyState < 2 || v.videoWidth === 0) return;
    if (this.encoding || !this.canSend()) {
      this.skipped += 1;
      return;
    }
    const scale = Math.max(FRAME_WIDTH / v.videoWidth, FRAME_HEIGHT / v.videoHeight);
    const sw = FRAME_WIDTH / scale;
    const sh = FRAME_HEIGHT / scale;
    this.ctx.drawImage(v, (v.videoWidth - sw) / 2, (v.videoHeight - sh) / 2, sw, sh, 0, 0, FRAME_WIDTH, FRAME_HEIGHT);
    this.encoding = true;
    this.canvas.toBlob(
      (blob) => {
        this.encoding = false;
        if (!blob || !this.running) return;
        blob.arrayBuffer().then((buf) => this.onFrame(buf));
      },
      "image/jpeg",
      JPEG_QUALITY,
    );
  }

  stop() {
    clearTimeout(this.timer);
    this.timer = null;
    if (!this.stream) return;
    for (const t of this.stream.getTracks()) t.stop();
    this.stream = null;
    this.video.srcObject = null;
  }
}
