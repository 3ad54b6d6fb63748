//! Where speech goes after the speech player: through a loopback WebRTC connection that Chrome's echo canceller
//! covers, or straight to the WebAudio destination.
//
// Chrome's echo canceller subtracts only what WebRTC itself plays: sound from Web Audio reaches the loudspeakers
// unseen by it (chromium bug 687574), and with loudspeakers instead of headphones the agent would hear itself. The
// known workaround, done here, sends the speech through a peer connection to the same page (a local loopback
// with no server involved) and plays what arrives in an `<audio>` element, which the canceller does see. It costs
// some delay (Opus frames, the receiver's jitter buffer); a probe on the received stream measures it, and the
// receiver's statistics follow its jitter buffer (playback-delay.js), so that the clock visemes are drawn on can
// run behind the audio clock by the same amount, moment by moment.
//
// The direct route is the fallback where WebRTC is missing or the loopback does not connect within a few seconds
// (no network interface for a host candidate, a policy that blocks it), and the choice with `?playback=direct`.

import { DelayEstimator, FRAME_S, MATCH_FRAMES } from "./playback-delay.js";

/**
 * The delay assumed for the loopback before a stretch of speech is matched, where WebRTC sizes the receiver's jitter
 * buffer: the middle of what tests/playback.rs measured for the first stretch across runs (45 ms in CI, 90-100 ms
 * on a quiet machine). The buffer's reading is not used for this guess: read during the silence before the first
 * utterance it overstated the buffer the first stretch then had (55 ms read, about 21 ms held, in CI), which put
 * the mouth 45 ms behind the sound.
 */
const LOOPBACK_INITIAL_DELAY_S = 0.07;
/**
 * The part of the delay a held jitter buffer does not explain (the Opus frame, the element's output and the probe's
 * input), assumed with `?playbackbuffer=N` until a stretch of speech is matched: 24-44 ms measured in
 * tests/playback.rs.
 */
const LOOPBACK_FIXED_GUESS_S = 0.035;
const CONNECT_TIMEOUT_MS = 5000;
/** How often the receiver's statistics are read: its jitter buffer moves within an utterance on a busy machine. */
const STATS_EVERY_MS = 250;


/** Web Audio straight to the output: nothing added, nothing the echo canceller sees. */
export class DirectRoute {
  constructor(ctx) {
    this.kind = "direct";
    this.input = ctx.destination;
    this.delayS = 0;
  }

  /** Nothing to measure here: the route adds no delay. */
  sent() {}

  /** The debug state of a direct route, also the player's before any route exists. */
  static idleState() {
    return { route: "direct", delayMs: 0, measuredMs: [], pairs: [], packetsReceived: 0, jitterBufferMs: 0 };
  }

  debugState() {
    return DirectRoute.idleState();
  }
}

/** Speech through a loopback peer connection and an `<audio>` element. Build it with `LoopbackRoute.open`. */
export class LoopbackRoute {
  constructor(parts) {
    this.kind = "loopback";
    this.input = parts.input;
    // Held for the route's life: the sound flows only while both connections and the element exist.
    this.sender = parts.sender;
    this.receiver = parts.receiver;
    this.element = parts.element;
    this.ctx = parts.ctx;
    // A held buffer's reading is its target from the start; a buffer WebRTC sizes moves once speech flows.
    this.estimator = new DelayEstimator(LOOPBACK_INITIAL_DELAY_S, parts.held ? LOOPBACK_FIXED_GUESS_S : null);
    this.packetsReceived = 0;
    /** The receiver's cumulative jitter-buffer figures at the last reading, for the mean since. */
    this.lastBuffer = null;
    /**
     * Recent measurements: [{utterance, appliedMs, measuredMs, bufferMs, score}], the shift in effect when the middle of the
     * matched stretch was heard, and the delay its sound took; what the sync test compares.
     */
    this.pairs = [];
    /**
     * Which utterance was sent at audio time `sentS`, and the shift of the visemes drawn when it was heard at
     * `heardS` (set by the player).
     */
    this.tagAt = (_sentS, _heardS) => null;
    this.statsTimer = setInterval(() => this.pollStats(), STATS_EVERY_MS);
    this.pollStats();
    parts.probe.port.onmessage = (ev) => {
      const { first, values } = ev.data ?? {};
      if (!Number.isInteger(first) || !(values instanceof Float32Array)) return;
      this.estimator.received.addFrames(first, values);
      const upTo = first + values.length - 1;
      const m = this.estimator.match(upTo);
      if (!m) return;
      // The stretch's middle, as it was heard, and as it was sent.
      const heardS = (upTo - MATCH_FRAMES / 2) * FRAME_S;
      const tag = this.tagAt(heardS - m.delayS, heardS) ?? {};
      this.pairs.push({
        utterance: tag.utterance ?? null,
        appliedMs: (tag.appliedS ?? 0) * 1000,
        measuredMs: m.delayS * 1000,
        bufferMs: m.bufferedS === null ? null : m.bufferedS * 1000,
        score: m.score,
      });
      if (this.pairs.length > 32) this.pairs.shift();
    };
  }

  /**
   * Connects the loopback: a MediaStreamDestination feeds one peer connection, the other plays what it receives.
   * `bufferMs` holds the receiver's jitter buffer at that many milliseconds (where the browser allows it: Chrome's
   * `jitterBufferTarget`) instead of letting WebRTC size it. Rejects when WebRTC is missing or the connection does
   * not come up in time.
   * @param {AudioContext} ctx
   * @param {{bufferMs?: number | null}} options
   */
  static async open(ctx, { bufferMs = null } = {}) {
    if (typeof RTCPeerConnection !== "function") throw new Error("no RTCPeerConnection in this browser");
    const input = ctx.createMediaStreamDestination();
    const sender = new RTCPeerConnection();
    const receiver = new RTCPeerConnection();
    const close = () => {
      sender.close();
      receiver.close();
    };
    try {
      sender.onicecandidate = (ev) => ev.candidate && receiver.addIceCandidate(ev.candidate).catch(() => {});
      receiver.onicecandidate = (ev) => ev.candidate && sender.addIceCandidate(ev.candidate).catch(() => {});
      const track = input.stream.getAudioTracks()[0];
      sender.addTrack(track, input.stream);
      const arrived = new Promise((resolve) => {
        receiver.ontrack = (ev) => resolve(ev.streams[0] ?? new MediaStream([ev.track]));
      });
      const offer = await sender.createOffer();
      await sender.setLocalDescription(offer);
      await receiver.setRemoteDescription(offer);
      const answer = await receiver.createAnswer();
      await receiver.setLocalDescription(answer);
      // Speech, not music: mono Opus at a speech-transparent rate, with 10 ms frames where the encoder allows,
      // which halves the packetisation delay of the default 20 ms.
      const sdp = (answer.sdp ?? "").replace(/(a=fmtp:\d+ [^\r\n]*useinbandfec=1)/, "$1;stereo=0;maxaveragebitrate=64000");
      await sender.setRemoteDescription({ type: "answer", sdp: `${sdp.trimEnd()}\r\na=ptime:10\r\n` });
      const stream = await withTimeout(arrived, CONNECT_TIMEOUT_MS, "no track arrived over the loopback");
      if (bufferMs !== null) {
        const rtp = receiver.getReceivers()[0];
        if (rtp && "jitterBufferTarget" in rtp) rtp.jitterBufferTarget = bufferMs;
        else console.warn("this browser cannot hold the playback jitter buffer; WebRTC sizes it");
      }
      await withTimeout(connected(receiver), CONNECT_TIMEOUT_MS, "the loopback connection did not come up");

      const element = new Audio();
      element.srcObject = stream;
      element.autoplay = true;
      // An element that may not play (autoplay policy without a user gesture) would make speech silent: the
      // route is used only once it plays.
      await element.play();

      await ctx.audioWorklet.addModule(new URL("./envelope-probe-worklet.js", import.meta.url));
      const probe = new AudioWorkletNode(ctx, "envelope-probe", { numberOfInputs: 1, numberOfOutputs: 0 });
      ctx.createMediaStreamSource(stream).connect(probe);
      return new LoopbackRoute({ ctx, input, sender, receiver, element, probe, held: bufferMs !== null });
    } catch (e) {
      close();
      throw e;
    }
  }

  /** The delay to add to the viseme schedule now (seconds). */
  get delayS() {
    return this.estimator.delayS;
  }

  /** `block` (at `rate`) enters the route at audio time `startS`. */
  sent(block, startS, rate) {
    this.estimator.sent.add(block, startS, rate);
  }

  async pollStats() {
    try {
      const report = await this.receiver.getStats();
      report.forEach((s) => {
        if (s.type !== "inbound-rtp" || s.kind !== "audio") return;
        this.packetsReceived = s.packetsReceived ?? 0;
        // Cumulative: the seconds every sample let out spent in the buffer, and how many were let out.
        const total = s.jitterBufferDelay;
        const count = s.jitterBufferEmittedCount;
        if (!Number.isFinite(total) || !Number.isFinite(count)) return;
        const last = this.lastBuffer;
        this.lastBuffer = { total, count };
        if (last && count > last.count) {
          this.estimator.jitter.add(this.ctx.currentTime, (total - last.total) / (count - last.count));
        }
      });
    } catch {
      // A closed connection has no stats; the figures stay where they were.
    }
  }

  debugState() {
    return {
      route: this.kind,
      delayMs: this.delayS * 1000,
      measuredMs: this.estimator.measured.map((s) => s * 1000),
      pairs: this.pairs.slice(),
      packetsReceived: this.packetsReceived,
      jitterBufferMs: (this.estimator.jitter.latestS ?? 0) * 1000,
    };
  }
}

/** Resolves when `pc` is connected; rejects when it fails. */
function connected(pc) {
  return new Promise((resolve, reject) => {
    const check = () => {
      if (pc.connectionState === "connected") resolve();
      else if (pc.connectionState === "failed" || pc.connectionState === "closed") reject(new Error(`loopback ${pc.connectionState}`));
    };
    pc.addEventListener("connectionstatechange", check);
    check();
  });
}

function withTimeout(promise, ms, what) {
  let timer;
  const timeout = new Promise((_, reject) => {
    timer = setTimeout(() => reject(new Error(what)), ms);
  });
  return Promise.race([promise, timeout]).finally(() => clearTimeout(timer));
}
