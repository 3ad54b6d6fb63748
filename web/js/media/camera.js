//! Camera capture: getUserMedia -> preview <video> -> 640x360 JPEG frames at an adjustable frame rate.
//
// Frames are scaled to cover 640x360 (centre crop, like the preview's object-fit: cover), so the detection
// coordinates the server sends line up with the preview. Where the browser has MediaStreamTrackProcessor (Chrome,
// Edge), the camera's frames go straight to a worker that paces, scales and encodes them, so the avatar's drawing on
// the main thread cannot slow the camera down; elsewhere a timer grabs ImageBitmaps for the same worker. A frame is
// skipped, not queued, while two are already being encoded or while the socket has a backlog (`skipped` counts).

import { explainMediaError } from "./media-errors.js";

export const FRAME_WIDTH = 640;
export const FRAME_HEIGHT = 360;
const JPEG_QUALITY = 0.75;
const MAX_IN_FLIGHT = 2;

export class Camera {
  /** `onFrame(ArrayBuffer jpeg)` is called per frame; `canSend()` says whether the link can take one now. */
  constructor(video, onFrame, canSend) {
    this.video = video;
    this.onFrame = onFrame;
    this.canSend = canSend;
    this.stream = null;
    this.fps = 15;
    this.worker = null;
    this.timer = null;
    this.inFlight = 0;
    this.paced = null;
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
    this.inFlight = 0;
    this.worker = new Worker(new URL("./jpeg-worker.js", import.meta.url));
    this.worker.onmessage = (ev) => {
      this.inFlight = Math.max(0, this.inFlight - 1);
      if (ev.data.error) console.warn("camera: JPEG encoding failed:", ev.data.error);
      else if (!this.running) return;
      else if (this.canSend()) this.onFrame(ev.data.jpeg, ev.data.capturedAt);
      else this.skipped += 1;
    };
    this.video.srcObject = stream;
    await this.video.play().catch(() => {});
    for (const track of stream.getVideoTracks()) {
      track.addEventListener("ended", () => this.stop());
    }
    const track = stream.getVideoTracks()[0];
    if (typeof MediaStreamTrackProcessor === "function" && track) {
      const { readable } = new MediaStreamTrackProcessor({ track });
      const msg = { type: "stream", readable, fps: this.fps, quality: JPEG_QUALITY, width: FRAME_WIDTH, height: FRAME_HEIGHT };
      this.worker.postMessage(msg, [readable]);
      this.paced = "worker";
    } else {
      this.paced = "timer";
      this.nextAt = performance.now();
      this.tick();
    }
  }

  /** Changes the capture rate (the server's advice, 5..15 fps). */
  setFps(fps) {
    if (!Number.isFinite(fps)) return;
    this.fps = Math.max(1, Math.min(15, fps));
    this.worker?.postMessage({ type: "fps", fps: this.fps });
  }

  tick() {
    if (!this.running) return;
    const now = performance.now();
    const interval = 1000 / this.fps;
    // Keep a steady cadence: schedule from the ideal time, not from when the timer happened to fire, so a late
    // timer is made up by the next one; after a long stall (more than a frame behind) start afresh.
    this.nextAt += interval;
    if (this.nextAt < now - interval) this.nextAt = now;
    this.timer = setTimeout(() => this.tick(), Math.max(0, this.nextAt - now));
    this.capture();
  }

  capture() {
    const v = this.video;
    if (v.readyState < 2 || v.videoWidth === 0) return;
    if (this.inFlight >= MAX_IN_FLIGHT || !this.canSend()) {
      this.skipped += 1;
      return;
    }
    const scale = Math.max(FRAME_WIDTH / v.videoWidth, FRAME_HEIGHT / v.videoHeight);
    const sw = FRAME_WIDTH / scale;
    const sh = FRAME_HEIGHT / scale;
    this.inFlight += 1;
    const capturedAt = performance.timeOrigin + performance.now();
    createImageBitmap(v, (v.videoWidth - sw) / 2, (v.videoHeight - sh) / 2, sw, sh, {
      resizeWidth: FRAME_WIDTH,
      resizeHeight: FRAME_HEIGHT,
      resizeQuality: "medium",
    }).then(
      (bitmap) => this.worker.postMessage({ type: "bitmap", bitmap, quality: JPEG_QUALITY, capturedAt }, [bitmap]),
      (err) => {
        this.inFlight -= 1;
        console.warn("camera: frame grab failed:", err);
      },
    );
  }

  stop() {
    clearTimeout(this.timer);
    this.timer = null;
    if (!this.stream) return;
    for (const t of this.stream.getTracks()) t.stop();
    this.stream = null;
    this.video.srcObject = null;
    this.worker?.terminate();
    this.worker = null;
  }
}
