//! The animated avatar: turns commands (blink, gaze, visemes, mood) into a face pose every animation frame.

import { frameClock } from "../panels/frame-clock.js";
import { trackCanvasSize } from "../panels/hidpi-canvas.js";
import { drawFace, restPose } from "./face.js";
import { BlinkController } from "./blink.js";
import { GazeController } from "./gaze.js";
import { expression } from "./moods.js";
import { mouthShape } from "./visemes.js";
import { VisemeTrack } from "./viseme-track.js";

const MOOD_TAU_MS = 160;
/** Between blinks and speech the face only breathes and its gaze drifts: 12 fps is smooth enough for that and
 * leaves the page's CPU to the microphone and the camera. Blinks, speech and commands draw at the clock's cap. */
const CALM_FRAME_MS = 83;
/** Eyes and head on their way to a new gaze target (the faces module sends one per camera frame) draw at the
 * camera's 15 fps; a blink and speech at the frame clock's cap. */
const TURN_FRAME_MS = 66;
const MOUTH_TAU_MS = 30; // co-articulation: shapes blend instead of snapping
const FRAME_LOG = 1200; // frames whose cost the debug hook keeps (~20 s at 60 fps)

export class Avatar {
  /**
   * `audioClock()` returns the speech player's clock in seconds (the time visemes are scheduled on).
   * `syncFrames` makes each frame wait until the canvas is really drawn (a one-pixel read forces the deferred
   * rasterisation), so the benchmark's frame cost is the drawing's, as the 3D head's is with gl.finish.
   */
  constructor(canvas, audioClock, { syncFrames = false } = {}) {
    this.syncFrames = syncFrames;
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.audioClock = audioClock;
    this.blinks = new BlinkController();
    this.gaze = new GazeController();
    this.track = new VisemeTrack();
    this.pose = restPose();
    this.moodName = "neutral";
    this.moodTarget = expression("neutral");
    this.mood = { ...this.moodTarget };
    this.viseme = "sil";
    this.last = performance.now();
    this.lastDraw = 0;
    this.frameMs = [];
    this.size = { w: 0, h: 0 };
    trackCanvasSize(canvas, this.ctx, (w, h) => {
      this.size = { w, h };
      this.wake?.();
    });
    this.frames = 0;
    this.wake = frameClock().add((now) => this.frame(now));
  }

  blink(phases, fromServer = true) {
    this.blinks.blink(performance.now(), phases, fromServer);
    this.wake();
  }

  lookAt(x, y) {
    this.gaze.look(performance.now(), x, y);
    this.wake();
  }

  setMood(name, intensity = 1) {
    this.moodName = name;
    this.moodTarget = expression(name, intensity);
    this.wake();
  }

  /** Schedules viseme `items` of `utterance` whose sample 0 plays at audio time `startS`. */
  scheduleVisemes(utterance, startS, items) {
    this.track.add(utterance, startS, items);
    this.wake();
  }

  stopSpeech(utterance) {
    this.track.clear(utterance);
    this.wake();
  }

  /** Draws one frame; returns when the next is wanted: at the cap while it blinks or speaks, calm otherwise, and
   * in time for the next blink the page does by itself. */
  frame(now) {
    this.draw(now);
    if (this.blinks.current !== null || this.track.pending > 0) return now;
    if (this.gazeMoving) return now + TURN_FRAME_MS;
    const nextBlink = this.blinks.owner === "page" ? this.blinks.nextAuto : Infinity;
    return Math.min(now + CALM_FRAME_MS, Math.max(now, nextBlink));
  }

  draw(now) {
    this.frames += 1;
    const dt = Math.min(100, Math.max(0, now - this.last));
    this.last = now;
    this.lastDraw = now;
    const start = performance.now();
    this.step(now, dt);
    if (this.size.w > 0) {
      const t0 = performance.now();
      drawFace(this.ctx, this.size.w, this.size.h, this.pose);
      if (this.syncFrames) this.ctx.getImageData(0, 0, 1, 1);
      // A running mean of the drawing cost, for the debug hook (the page must leave time for the camera).
      this.drawMs = this.drawMs === undefined ? performance.now() - t0 : this.drawMs * 0.95 + (performance.now() - t0) * 0.05;
    }
    // Each frame's time and whole cost (animation and drawing), for the renderer benchmark's percentiles.
    this.frameMs.push([Math.round(now), performance.now() - start]);
    if (this.frameMs.length > FRAME_LOG) this.frameMs.shift();
  }

  step(now, dt) {
    const p = this.pose;
    const km = 1 - Math.exp(-dt / MOOD_TAU_MS);
    for (const k of Object.keys(this.mood)) {
      this.mood[k] += (this.moodTarget[k] - this.mood[k]) * km;
    }
    const was = { eyeX: p.eyeX, eyeY: p.eyeY, yaw: p.yaw, pitch: p.pitch / 0.6 };
    const g = this.gaze.update(now, dt);
    // A saccade or a head turn in progress draws at the cap; a settled gaze only drifts.
    this.gazeMoving = Math.abs(g.eyeX - was.eyeX) + Math.abs(g.eyeY - was.eyeY) + Math.abs(g.yaw - was.yaw) + Math.abs(g.pitch - was.pitch) > 0.002;
    p.eyeX = g.eyeX;
    p.eyeY = g.eyeY;
    p.yaw = g.yaw;
    p.pitch = g.pitch * 0.6;
    p.roll = this.mood.roll + g.yaw * -0.02;
    p.breath = Math.sin(now / 900);

    const blink = this.blinks.update(now);
    // Looking down lowers the upper lid a little; a squint narrows the eye.
    const lidBase = Math.max(0.1, Math.min(1.08, 1 - this.mood.squint - Math.max(0, g.eyeY) * 0.15));
    p.lid = blink * lidBase;

    p.browRaise = this.mood.browRaise;
    p.browInner = this.mood.browInner;
    p.smile = this.mood.smile;
    p.blush = this.mood.blush;

    this.viseme = this.track.at(this.audioClock());
    const shape = mouthShape(this.viseme);
    const kv = 1 - Math.exp(-dt / MOUTH_TAU_MS);
    const jawWanted = Math.min(1, shape.jaw + (this.viseme === "sil" ? this.mood.jaw : 0));
    p.jaw += (jawWanted - p.jaw) * kv;
    p.mouthWidth += (shape.mouthWidth - p.mouthWidth) * kv;
    p.round += (shape.round - p.round) * kv;
    p.teeth += (shape.teeth - p.teeth) * kv;
    p.tongue += (shape.tongue - p.tongue) * kv;
    p.lipPress += (shape.lipPress - p.lipPress) * kv;
  }

  /** A snapshot for `window.agentDebug`. */
  debugState() {
    return {
      eyelid: this.pose.lid,
      blinks: this.blinks.completed,
      blinkOwner: this.blinks.owner,
      gaze: { ...this.gaze.target },
      gazeCommands: this.gaze.commands,
      eyeOffset: { x: this.gaze.eye.x, y: this.gaze.eye.y },
      head: { yaw: this.pose.yaw, pitch: this.pose.pitch },
      mood: this.moodName,
      viseme: this.viseme,
      jaw: this.pose.jaw,
      drawMs: this.drawMs ?? 0,
      renderer: "2d",
      frameMs: this.frameMs.slice(),
      frames: this.frames,
    };
  }
}
