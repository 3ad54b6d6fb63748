//! The status strip: connection, role, frame rates in and out, microphone level, drops and round-trip time.

export class StatusStrip {
  constructor(doc) {
    const $ = (id) => doc.getElementById(id);
    this.el = {
      connDot: $("st-conn-dot"), conn: $("st-conn"), role: $("st-role"), fpsOut: $("st-fps-out"),
      audOut: $("st-aud-out"), fpsIn: $("st-fps-in"), level: $("st-level"), levelBar: $("st-level-bar"),
      drops: $("st-drops"), rtt: $("st-rtt"), pill: $("conn-pill"), voice: $("st-voice"), camera: $("st-camera"),
    };
    this.prev = null;
    this.rates = null;
  }

  /**
   * Refreshes from `s` = {connection, role, sentVideo, sentAudio, received, levelDb, drops, rttMs, voice, camera}
   * (the last two: the latency figures' text, panels/latency.js).
   */
  update(s, nowMs) {
    const e = this.el;
    e.conn.textContent = s.connection;
    e.connDot.dataset.state = s.connection;
    e.pill.textContent = s.connection === "open" ? "connected" : s.connection;
    e.pill.dataset.state = s.connection;
    e.role.textContent = s.role;
    if (this.prev) {
      const dt = (nowMs - this.prev.t) / 1000;
      if (dt > 0) {
        // Rates are smoothed over a few seconds: a single late timer should not make the figures jump.
        const ema = (old, now) => (old === undefined ? now : old + (now - old) * 0.3);
        this.rates = {
          video: ema(this.rates?.video, (s.sentVideo - this.prev.sentVideo) / dt),
          audio: ema(this.rates?.audio, (s.sentAudio - this.prev.sentAudio) / dt),
          received: ema(this.rates?.received, (s.received - this.prev.received) / dt),
        };
        e.fpsOut.textContent = this.rates.video.toFixed(1);
        e.audOut.textContent = this.rates.audio.toFixed(0);
        e.fpsIn.textContent = this.rates.received.toFixed(0);
      }
    }
    this.prev = { t: nowMs, sentVideo: s.sentVideo, sentAudio: s.sentAudio, received: s.received };
    const db = Number.isFinite(s.levelDb) ? s.levelDb : -Infinity;
    e.level.textContent = Number.isFinite(db) ? db.toFixed(0) : "–∞";
    e.levelBar.style.width = `${Math.max(0, Math.min(100, ((db + 60) / 60) * 100))}%`;
    e.drops.textContent = String(s.drops);
    e.rtt.textContent = s.rttMs === null ? "–" : s.rttMs.toFixed(1);
    e.voice.textContent = s.voice;
    e.camera.textContent = s.camera;
  }
}
