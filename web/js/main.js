//! Boots the page: connects the link, builds the avatar and panels, and runs the microphone/camera role.

import { createAvatar, DEFAULT_RENDERER } from "./avatar/renderer.js";
import { decodeSpeech, KIND } from "./link/frames.js";
import { Link, SEND_BACKLOG_LIMIT } from "./link/link.js";
import { audioClock, audioContext } from "./media/audio-context.js";
import { Camera } from "./media/camera.js";
import { Microphone } from "./media/microphone.js";
import { LoopbackRoute } from "./media/playback-route.js";
import { SpeechPlayer } from "./media/speech.js";
import { playedMessage } from "./media/played.js";
import { frameClock } from "./panels/frame-clock.js";
import { Overlay } from "./panels/overlay.js";
import { Latencies } from "./panels/latency.js";
import { RuleTrace } from "./panels/rules.js";
import { Spectrum } from "./panels/spectrum.js";
import { StatusStrip } from "./panels/status.js";
import { fill, pickLanguage, wordsFor } from "./panels/words.js";
import { installDebugHook } from "./debug.js";

const params = new URLSearchParams(location.search);
const autostart = params.get("autostart") === "1";
const $ = (id) => document.getElementById(id);

// The page's words: `?lang=` if it names a language the page knows, else the agent's (from the welcome).
let language = pickLanguage(params.get("lang"), null);
let words = wordsFor(language);
function applyLanguage(next) {
  language = next;
  words = wordsFor(language);
  document.documentElement.lang = language;
  page.language = language;
  for (const el of document.querySelectorAll("[data-words]")) el.textContent = words[el.dataset.words];
  for (const el of document.querySelectorAll("[data-words-title]")) el.title = words[el.dataset.wordsTitle];
  for (const el of document.querySelectorAll("[data-words-placeholder]")) {
    el.placeholder = words[el.dataset.wordsPlaceholder];
  }
}

const link = new Link({ autostart });
// Visemes are drawn on the clock of what is heard: the audio clock less the playback route's delay now (the
// speech player below sets it; the avatar may draw before that).
let heardTime = (/** @type {number} */ nowS) => nowS;
const heardClock = () => heardTime(audioClock());
// The 3D head where WebGL is hardware-accelerated, the 2D face otherwise (the page's CPU budget on a machine without
// a GPU, issue 47); `?avatar=3d|2d` asks for one, and the 3D head falls back to the 2D face where it cannot run.
const { avatar, renderer: avatarRenderer, reason: avatarReason } = await createAvatar(
  $("avatar"),
  heardClock,
  params.get("avatar") ?? DEFAULT_RENDERER,
  {
    syncFrames: params.get("avatarsync") === "1",
    quality: {
      // `avatarquality=full`: GPU settings (the full model, PBR materials, antialiasing, full resolution) even on
      // software WebGL.
      ...(params.get("avatarquality") === "full" ? { software: false, adaptive: false } : {}),
      // `avatarview=RADIANS`: the camera turned around the head (the tests' three-quarter view).
      view: { yaw: Number(params.get("avatarview") ?? 0) || 0 },
    },
  },
);
const overlay = new Overlay($("overlay"));
const spectrum = new Spectrum($("spectrum"));
const rules = new RuleTrace($("rules"), $("rules-meta"));
const strip = new StatusStrip(document);

const pendingVisemes = new Map(); // utterance -> items waiting for their audio
const speech = new SpeechPlayer((utterance, startS) => {
  const items = pendingVisemes.get(utterance);
  if (items) {
    pendingVisemes.delete(utterance);
    avatar.scheduleVisemes(utterance, startS, items);
  }
  // When the user will hear it begin, for the turn's trace (docs/telemetry.md); the holder's page is the one heard.
  const played = playedMessage(
    utterance,
    startS,
    speech.routeDelayS,
    audioContext().currentTime,
    performance.timeOrigin + performance.now(),
    link.clock.offset(),
  );
  if (played && page.role === "holder") link.sendJson(played);
});
heardTime = (nowS) => speech.heardTime(nowS);

// Speech plays through a loopback peer connection so that Chrome's echo canceller removes it from the microphone
// (loudspeakers, not headphones); `?playback=direct` keeps the plain Web Audio path. It opens once the microphone
// runs: without a microphone there is no echo to cancel, and with its permission granted the browser offers the
// loopback plain host addresses rather than mDNS names that might not resolve. A page the browser does not yet let
// play sound (no user gesture) tries again on the first click or key.
let playbackOpening = false; // opening or open: the route is set up once per page
async function openEchoSafePlayback() {
  if (playbackOpening || params.get("playback") === "direct") return;
  playbackOpening = true;
  try {
    // `?playbackbuffer=N` holds the loopback's jitter buffer at N ms (0-4000) instead of letting WebRTC resize it.
    const buffer = Number.parseInt(params.get("playbackbuffer") ?? "", 10);
    const bufferMs = Number.isInteger(buffer) && buffer >= 0 && buffer <= 4000 ? buffer : null;
    speech.useRoute(await LoopbackRoute.open(audioContext(), { bufferMs }));
    speech.routeError = null;
  } catch (e) {
    speech.routeError = String(e?.message ?? e);
    console.warn("speech plays straight to the output, which the echo canceller does not cover:", speech.routeError);
    playbackOpening = false;
    if (e?.name === "NotAllowedError") {
      const retry = () => {
        window.removeEventListener("pointerdown", retry);
        window.removeEventListener("keydown", retry);
        openEchoSafePlayback();
      };
      window.addEventListener("pointerdown", retry);
      window.addEventListener("keydown", retry);
    }
  }
}

const page = {
  role: "none", // none | pending | holder | busy
  wantMic: false,
  wantCam: false,
  sent: { audio: 0, video: 0 },
  serverDrops: 0,
  /** Audio chunks the server dropped because the hub side fell behind (its status's audio_dropped). */
  audioDropped: 0,
  lastError: null,
  videoFps: 15,
  /** The recorder module's state, as Agent.recording last said. */
  recording: { recording: false, file: null, started_ms: null, messages: 0 },
  /** The language of the page's words ("en" or "it"). */
  language: "en",
  /** Welcomes received on this page's sockets (the words follow the latest). */
  welcomes: 0,
};

/** The status strip's "speech end -> reply audio" and "camera capture -> box drawn" figures. */
const latencies = new Latencies();

const mic = new Microphone(
  (pcm) => {
    if (page.role === "holder" && link.sendMedia(KIND.AUDIO, pcm)) page.sent.audio += 1;
  },
  { echoCancellation: params.get("aec") !== "0" },
);
const camera = new Camera(
  $("camera"),
  (jpeg, capturedAt) => {
    if (page.role === "holder" && link.sendMedia(KIND.VIDEO, jpeg)) {
      page.sent.video += 1;
      if (Number.isFinite(capturedAt)) latencies.frameSent(capturedAt, performance.timeOrigin + performance.now());
    }
  },
  () => link.backlog < SEND_BACKLOG_LIMIT,
);

// The canvases' calm drawing rides on the camera preview's frames, which the compositor makes anyway
// (panels/frame-clock.js): on a machine without a GPU every frame of its own costs.
frameClock().pace((cb) => {
  const video = /** @type {HTMLVideoElement} */ ($("camera"));
  if (!camera.running || video.paused || video.readyState < 2 || !("requestVideoFrameCallback" in video)) return false;
  video.requestVideoFrameCallback((now) => cb(now));
  return true;
});

// ---- user controls -------------------------------------------------------------------------------------------

$("mic-btn").addEventListener("click", () => toggle("mic"));
$("cam-btn").addEventListener("click", () => toggle("cam"));

function toggle(which) {
  clearNotice();
  if (which === "mic") page.wantMic = !page.wantMic;
  else page.wantCam = !page.wantCam;
  if (which === "mic" && !page.wantMic) mic.stop();
  if (which === "cam" && !page.wantCam) camera.stop();
  syncRole();
  refreshButtons();
}

/** Claims the role when the page wants media, releases it when it wants none, starts what the role allows. */
function syncRole() {
  const wants = page.wantMic || page.wantCam;
  if (wants && page.role === "none" && link.isOpen) {
    page.role = "pending";
    link.sendJson({ type: "claim" });
  } else if (!wants && (page.role === "holder" || page.role === "pending" || page.role === "busy")) {
    page.role = "none";
    link.sendJson({ type: "release" });
    showBanner(null);
  }
  if (page.role === "holder") startWanted();
  else reportMedia();
}

async function startWanted() {
  const tasks = [];
  if (page.wantMic && !mic.running) tasks.push(startDevice(mic, "mic"));
  if (page.wantCam && !camera.running) tasks.push(startDevice(camera, "cam"));
  await Promise.all(tasks);
  reportMedia();
  refreshButtons();
  // Both devices failed: give the role back so someone else can talk to the agent.
  if (!page.wantMic && !page.wantCam) syncRole();
}

async function startDevice(device, which) {
  try {
    await device.start();
    if (which === "mic") openEchoSafePlayback();
  } catch (err) {
    if (which === "mic") page.wantMic = false;
    else page.wantCam = false;
    showNotice(err.message);
  }
}

let reported = { audio: null, video: null };
function reportMedia() {
  const now = { audio: page.role === "holder" && mic.running, video: page.role === "holder" && camera.running };
  if (now.audio !== reported.audio || now.video !== reported.video) {
    if (link.sendJson({ type: "media", ...now })) reported = now;
  }
  $("cam-meta").textContent = camera.running ? `${camera.fps} fps` : words.cameraOff;
  $("preview-empty").hidden = camera.running;
}

function refreshButtons() {
  const set = (id, on, start, stop) => {
    const b = $(id);
    b.dataset.on = String(on);
    b.querySelector(".btn-label").textContent = on ? stop : start;
  };
  set("mic-btn", page.wantMic, words.startMicrophone, words.stopMicrophone);
  set("cam-btn", page.wantCam, words.startCamera, words.stopCamera);
}

// Agent controls go to Agent.ctrl (docs/asr.md, docs/voice.md); the server accepts them only from the holder.
let asrOn = true;
$("asr-btn").addEventListener("click", () => {
  if (link.sendJson({ type: "ctrl", data: { asr: !asrOn } })) {
    asrOn = !asrOn;
    $("asr-btn").dataset.on = String(asrOn);
    showListening();
  }
});
function showListening() {
  $("asr-btn").textContent = asrOn ? words.listeningOn : words.listeningOff;
}
$("hush-btn").addEventListener("click", () => link.sendJson({ type: "ctrl", data: { speech: "stop" } }));
// The recorder module answers on Agent.recording; the button shows what it says, not what was asked.
$("rec-btn").addEventListener("click", () => {
  link.sendJson({ type: "ctrl", data: { record: !page.recording.recording } });
});
link.addEventListener("recording", (ev) => {
  page.recording = ev.detail.data;
  showRecording();
});
function showRecording() {
  const r = page.recording;
  $("rec-btn").dataset.on = String(r.recording);
  $("rec-btn").textContent = r.recording ? words.stopRecording : words.record;
  const name = r.file ? r.file.split("/").pop() : "";
  $("rec-state").textContent = r.error
    ? r.error
    : r.recording
      ? fill(words.recordingTo, { name })
      : r.file
        ? fill(words.saved, { name, messages: r.messages })
        : words.notRecording;
  $("rec-state").title = r.file ?? "";
}
$("say-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const text = $("say-text").value.trim();
  if (text && link.sendJson({ type: "ctrl", data: { say: text } })) $("say-text").value = "";
});

function refreshAgentControls() {
  const holder = page.role === "holder";
  for (const id of ["asr-btn", "hush-btn", "say-text", "say-btn", "rec-btn"]) $(id).disabled = !holder;
  $("agent-meta").textContent = holder ? words.holderMeta : words.notHolderMeta;
}

// ---- link events ---------------------------------------------------------------------------------------------

link.addEventListener("state", (ev) => {
  if (ev.detail.state !== "open") {
    page.role = "none";
    reported = { audio: null, video: null };
  }
});

link.addEventListener("welcome", (ev) => {
  // Connected again: an earlier refusal shown in the banner no longer holds.
  showBanner(null);
  applyLanguage(pickLanguage(params.get("lang"), ev.detail.language));
  latencies.speaksWith(ev.detail.voice);
  page.welcomes += 1;
  refreshButtons();
  refreshAgentControls();
  showListening();
  showRecording();
  reportMedia();
  spectrum.configure(ev.detail.fft);
  if (autostart) {
    page.wantMic = true;
    page.wantCam = true;
    refreshButtons();
  }
  syncRole();
});

link.addEventListener("role", (ev) => {
  const state = ev.detail.state;
  if (state === "granted") {
    page.role = "holder";
    showBanner(null);
    startWanted();
  } else if (state === "busy") {
    page.role = "busy";
    showBanner("Someone else is talking to the agent. You will take over when they leave.");
    mic.stop();
    camera.stop();
    reportMedia();
  } else if (state === "free" || state === "released") {
    if (page.role !== "none") page.role = "none";
    showBanner(null);
    syncRole();
  }
});

link.addEventListener("avatar", (ev) => handleAvatar(ev.detail.data));
link.addEventListener("detections", (ev) => overlay.show(ev.detail.data));
link.addEventListener("rules", (ev) => rules.add(ev.detail.data));
link.addEventListener("latency", (ev) => latencies.turn(ev.detail.data));
overlay.onDrawn = (frameTsUs, drawnMs) => latencies.detectionsDrawn(frameTsUs, drawnMs, (s) => link.clock.toPage(s));
link.addEventListener("spectrum", (ev) => spectrum.push(ev.detail.body));
link.addEventListener("speech", (ev) => {
  const s = decodeSpeech(ev.detail.body);
  if (s) speech.play(s.utterance, s.offset, s.pcm);
});
link.addEventListener("status", (ev) => {
  const st = ev.detail;
  const d = st.dropped ?? {};
  page.serverDrops = (d.video_queue ?? 0) + (d.to_page ?? 0);
  page.audioDropped = st.audio_dropped ?? 0;
  const fps = st.advice?.video_fps;
  if (Number.isFinite(fps)) {
    page.videoFps = fps;
    camera.setFps(fps);
  }
});
link.addEventListener("error", (ev) => {
  page.lastError = ev.detail.message ?? ev.detail.code ?? "error";
  console.warn("link:", page.lastError);
  // A refused session (signed out, too many pages) is something the user can act on: say it on the page.
  if (String(page.lastError).startsWith("cannot reach the agent: ")) {
    showBanner(String(page.lastError).slice("cannot reach the agent: ".length));
  }
});

function handleAvatar(cmd) {
  if (!cmd || typeof cmd.cmd !== "string") return;
  switch (cmd.cmd) {
    case "blink":
      avatar.blink(cmd, true);
      break;
    case "gaze":
      if (Number.isFinite(cmd.x) && Number.isFinite(cmd.y)) avatar.lookAt(cmd.x, cmd.y);
      break;
    case "mood":
      avatar.setMood(String(cmd.mood ?? "neutral"), Number.isFinite(cmd.intensity) ? cmd.intensity : 1);
      break;
    case "visemes": {
      const utterance = Number.isInteger(cmd.utterance) ? cmd.utterance : 0;
      const items = Array.isArray(cmd.items) ? cmd.items : [];
      const anchor = speech.anchorOf(utterance);
      if (anchor !== undefined && (utterance !== 0 || speech.speaking)) avatar.scheduleVisemes(utterance, anchor, items);
      else {
        // One utterance's cues come in several batches before its audio starts: keep them all, in order.
        const pending = pendingVisemes.get(utterance);
        if (pending) pending.push(...items);
        else pendingVisemes.set(utterance, items.slice());
      }
      break;
    }
    case "speech_stop":
      // A barge-in fades the reply out over 80 ms; a cancel stops it at once.
      speech.stop(cmd.barge_in === true ? 0.08 : 0);
      avatar.stopSpeech();
      pendingVisemes.clear();
      showCaption(null);
      break;
    case "say":
      showCaption(typeof cmd.text === "string" ? cmd.text : null);
      break;
    default:
      console.info("avatar: unknown command", cmd.cmd);
  }
}

// ---- notices, banner, caption --------------------------------------------------------------------------------

const notices = [];
function showNotice(text) {
  page.lastError = text;
  // Microphone and camera can fail together: show both messages, once each.
  if (!notices.includes(text)) notices.push(text);
  $("notice").textContent = notices.join(" ");
  $("notice").hidden = false;
}

function clearNotice() {
  notices.length = 0;
  $("notice").hidden = true;
}

function showBanner(text) {
  $("role-banner").hidden = !text;
  $("role-banner").textContent = text ?? "";
}

let captionTimer = null;
function showCaption(text) {
  clearTimeout(captionTimer);
  $("caption").hidden = !text;
  $("caption").textContent = text ?? "";
  if (text) {
    const hideWhenQuiet = () => {
      captionTimer = setTimeout(() => (speech.speaking ? hideWhenQuiet() : showCaption(null)), 1500);
    };
    hideWhenQuiet();
  }
}

// ---- status strip --------------------------------------------------------------------------------------------

setInterval(() => {
  strip.update(
    {
      connection: link.state,
      role: page.role,
      sentVideo: page.sent.video,
      sentAudio: page.sent.audio,
      received: link.receivedTotal,
      levelDb: mic.levelDb,
      drops: page.serverDrops + camera.skipped,
      rttMs: link.rttMs,
      voice: latencies.voiceText(),
      camera: latencies.camera.text(),
    },
    performance.now(),
  );
  reportMedia();
  refreshAgentControls();
}, 500);

installDebugHook({ avatar, avatarRenderer, avatarReason, link, page, camera, mic, spectrum, overlay, rules, speech, latencies });
refreshButtons();
link.start();
