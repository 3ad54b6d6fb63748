//! `window.agentDebug`: a read-only view of the page's state for end-to-end tests and for debugging by hand.

import { frameClock } from "./panels/frame-clock.js";

export function installDebugHook({ avatar, avatarRenderer, avatarReason, link, page, camera, mic, spectrum, overlay, rules, speech, latencies }) {
  const hook = {};
  const define = (name, get) => Object.defineProperty(hook, name, { get, enumerable: true });
  define("eyelid", () => avatar.debugState().eyelid);
  define("blinks", () => avatar.debugState().blinks);
  define("blinkOwner", () => avatar.debugState().blinkOwner);
  define("gaze", () => avatar.debugState().gaze);
  define("gazeCommands", () => avatar.debugState().gazeCommands);
  define("eyeOffset", () => avatar.debugState().eyeOffset);
  define("head", () => avatar.debugState().head);
  define("mood", () => avatar.debugState().mood);
  define("viseme", () => avatar.debugState().viseme);
  define("jaw", () => avatar.debugState().jaw);
  define("avatarDrawMs", () => avatar.debugState().drawMs);
  // Which renderer draws the avatar ("2d" or "3d"), and what only the 3D head has: its eyes' and head's
  // rotations (radians), morph weights, and a per-frame trace (audio time, mouth opening, blink) for timing tests;
  // for both, [page time, cost ms] of recent frames (avatarFrameMs).
  define("avatarRenderer", () => avatarRenderer);
  // Why the page chose it (renderer-choice.js).
  define("avatarReason", () => avatarReason);
  define("avatarFrameMs", () => avatar.debugState().frameMs ?? null);
  define("avatarQuality", () => avatar.debugState().quality ?? null);
  define("eyeRotation", () => avatar.debugState().eyeRotation ?? null);
  define("headRotation", () => avatar.debugState().headRotation ?? null);
  define("morphs", () => avatar.debugState().morphs ?? null);
  define("avatarTrace", () => avatar.debugState().trace ?? null);
  define("blinkLog", () => avatar.debugState().blinkLog ?? null);
  define("visemeSchedule", () => avatar.debugState().schedule ?? null);
  define("role", () => page.role);
  // The language of the page's words, and the microphone button's label as shown (both follow the welcome).
  define("language", () => page.language);
  define("welcomes", () => page.welcomes);
  define("micLabel", () => document.querySelector("#mic-btn .btn-label")?.textContent ?? null);
  // The recorder's last state (Agent.recording): recording, file, started_ms, messages, error.
  define("recording", () => ({ ...page.recording }));
  // The status strip's latencies: last and median of each, ms (null until measured).
  define("latency", () => ({
    voice: { last: latencies.voice.last, median: latencies.voice.median() },
    camera: { last: latencies.camera.last, median: latencies.camera.median() },
    clockOffsetMs: link.clock.offset(),
    behind: [...latencies.behind],
    engine: latencies.engine,
  }));
  define("connection", () => link.state);
  define("sent", () => ({ ...page.sent }));
  // Audio chunks the server dropped on its side of the link (its status's audio_dropped).
  define("audioDropped", () => page.audioDropped);
  // The page's frame clock (panels/frame-clock.js): frames asked of the browser and drawings made, since load.
  define("pageFrames", () => ({ frames: frameClock().frames, draws: frameClock().draws }));
  define("received", () => ({ ...link.received }));
  define("videoFps", () => camera.fps);
  define("cameraSkipped", () => camera.skipped);
  define("cameraPacing", () => camera.paced);
  define("micRunning", () => mic.running);
  define("cameraRunning", () => camera.running);
  define("micLevelDb", () => mic.levelDb);
  define("spectrumFrames", () => spectrum.frames);
  define("spectrumPeakHz", () => spectrum.peakHz);
  define("detections", () => overlay.count);
  define("overlayItems", () => overlay.items);
  define("rules", () => rules.count);
  define("speechChunks", () => speech.chunks);
  // The speech playback route: "loopback" (through a peer connection the echo canceller covers) or "direct", the
  // delay compensated in the viseme schedule, the measurements behind it (ms), RTP packets received, and why the
  // loopback is not in use when it is not.
  define("playback", () => speech.routeState());
  define("lastError", () => page.lastError);
  define("snapshot", () => {
    const out = {};
    for (const k of Object.keys(hook)) if (k !== "snapshot" && k !== "avatarTrace" && k !== "visemeSchedule" && k !== "avatarFrameMs") out[k] = hook[k];
    return out;
  });
  Object.defineProperty(window, "agentDebug", { value: Object.freeze(hook), configurable: false });
}
