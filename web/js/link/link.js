//! The page's end of the browser link: session, one WebSocket, reconnects, JSON control and binary media.

import { ServerClock } from "./clock.js";
import { decodeFrame, encodeFrame, KIND } from "./frames.js";

const RECONNECT_MIN_MS = 500;
const RECONNECT_MAX_MS = 5000;
const PING_EVERY_MS = 5000;
/** Above this many bytes waiting in the socket the page skips camera frames instead of queueing them. */
export const SEND_BACKLOG_LIMIT = 512 * 1024;

export class Link extends EventTarget {
  constructor({ autostart }) {
    super();
    this.autostart = autostart;
    this.ws = null;
    this.session = null;
    this.state = "connecting";
    this.seq = { [KIND.AUDIO]: 0, [KIND.VIDEO]: 0 };
    this.received = {};
    this.receivedTotal = 0;
    this.rttMs = null;
    /** The server's clock on the page's, from the pongs (link/clock.js). */
    this.clock = new ServerClock();
    this.backoff = RECONNECT_MIN_MS;
    this.pingTimer = null;
  }

  start() {
    this.connect();
  }

  async connect() {
    this.setState("connecting");
    try {
      if (!this.session) this.session = await requestSession();
      const url = new URL(this.session.link, location.href);
      url.protocol = location.protocol === "https:" ? "wss:" : "ws:";
      url.searchParams.set("session", this.session.session);
      const ws = new WebSocket(url);
      ws.binaryType = "arraybuffer";
      ws.onopen = () => this.opened();
      ws.onmessage = (ev) => this.message(ev.data);
      ws.onclose = (ev) => this.closed(ev);
      this.ws = ws;
    } catch (err) {
      this.emit("error", { message: `cannot reach the agent: ${err.message}` });
      this.scheduleReconnect(true);
    }
  }

  opened() {
    this.backoff = RECONNECT_MIN_MS;
    this.seq = { [KIND.AUDIO]: 0, [KIND.VIDEO]: 0 };
    this.setState("open");
    this.sendJson({ type: "hello", version: 1, client: "robot-agent-web", autostart: this.autostart });
    clearInterval(this.pingTimer);
    // One ping at once, so the server's clock is known before the first reply plays (its playback start is told
    // on that clock), then one every few seconds.
    const ping = () => this.sendJson({ type: "ping", t: performance.now() });
    ping();
    this.pingTimer = setInterval(ping, PING_EVERY_MS);
  }

  closed(ev) {
    clearInterval(this.pingTimer);
    this.ws = null;
    this.setState("closed", { code: ev.code, reason: ev.reason });
    // A refused session (expired after a long sleep, or the server restarted) needs a fresh token.
    if (ev.code === 1008 || ev.code === 1006) this.session = null;
    this.scheduleReconnect(false);
  }

  scheduleReconnect(grow) {
    const wait = this.backoff;
    if (grow || this.state === "closed") this.backoff = Math.min(RECONNECT_MAX_MS, this.backoff * 2);
    setTimeout(() => this.connect(), wait);
  }

  message(data) {
    this.receivedTotal += 1;
    if (typeof data === "string") {
      let msg;
      try {
        msg = JSON.parse(data);
      } catch {
        console.warn("link: text frame is not JSON", data.slice(0, 80));
        return;
      }
      const type = typeof msg.type === "string" ? msg.type : "unknown";
      this.received[type] = (this.received[type] ?? 0) + 1;
      if (type === "pong" && Number.isFinite(msg.t)) {
        const now = performance.now();
        this.rttMs = now - msg.t;
        this.clock.sample(performance.timeOrigin + msg.t, performance.timeOrigin + now, msg.server_ms);
      }
      this.emit(type, msg);
      return;
    }
    const frame = decodeFrame(data);
    if (!frame) {
      console.warn("link: binary frame with a bad header ignored");
      return;
    }
    const name = frame.kind === KIND.SPEECH ? "speech" : frame.kind === KIND.SPECTRUM ? "spectrum" : null;
    if (!name) {
      console.warn(`link: unknown binary kind 0x${frame.kind.toString(16)}`);
      return;
    }
    this.received[name] = (this.received[name] ?? 0) + 1;
    this.emit(name, frame);
  }

  get isOpen() {
    return this.ws !== null && this.ws.readyState === WebSocket.OPEN;
  }

  get backlog() {
    return this.ws ? this.ws.bufferedAmount : 0;
  }

  sendJson(msg) {
    if (!this.isOpen) return false;
    this.ws.send(JSON.stringify(msg));
    return true;
  }

  /** Sends one media frame of `kind`; returns false when the socket is not open. */
  sendMedia(kind, payload) {
    if (!this.isOpen) return false;
    const seq = this.seq[kind];
    this.seq[kind] = (seq + 1) >>> 0;
    this.ws.send(encodeFrame(kind, seq, payload));
    return true;
  }

  setState(state, detail = {}) {
    this.state = state;
    this.emit("state", { state, ...detail });
  }

  emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }
}

async function requestSession() {
  const res = await fetch("/api/session", { method: "POST", cache: "no-store" });
  if (res.status === 401) {
    throw new Error("signed out: open the address robot-agent printed at start (it ends in ?token=...) again");
  }
  if (!res.ok) {
    // The server says why (e.g. too many pages open); show its words.
    const reason = await res.json().then((b) => b?.error, () => null);
    throw new Error(reason ? String(reason) : `session refused (HTTP ${res.status})`);
  }
  const body = await res.json();
  if (typeof body.session !== "string" || typeof body.link !== "string") throw new Error("malformed session answer");
  return body;
}
