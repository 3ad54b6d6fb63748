//! The status strip: connection, role, frame rates in and out, microphone level, drops and round-trip time.

export class StatusStrip {
  constructor(doc) {
    const $ = (id) => doc.getElementById(id);
    this.el = {
      connDot: $("st-conn-dot"), conn: $("st-conn"), role: $("st-role"), fpsOut: $("st-fps-out"),
      audOut: $("st-aud-out"), fpsIn: $("st-fps-in"), level: $("st-level"), levelBar: $("st-level-bar"),
      drops: $("st-drops"), rtt: $("st-rtt"), pill: $("conn-pill"),
    };
    this.prev = null;
  }

  /** Refreshes from `s` = {connection, role, sentVideo, sentAudio, received, levelDb, drops, rttMs}. */
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
        e.fpsOut.textContent = ((s.sentVideo - this.prev.sentVideo) / dt).toFixed(1);
        e.audOut.textContent = ((s.sentAudio - this.prev.sentAudio) / dt).toFixed(0);
        e.fpsIn.textContent = ((s.received - this.prev.received) / dt).toFixed(0);
      }
    }
    this.prev = { t: nowMs, sentVideo: s.sentVideo, sentAudio: s.sentAudio, received: s.received };
    const db = Number.isFinite(s.levelDb) ? s.levelDb : -Infinity;
    e.level.textContent = Number.isFinite(db) ? db.toFixed(0) : "–∞";
    e.levelBar.style.width = `${Math.max(0, Math.min(100, ((db + 60) / 60) * 100))}%`;
    e.drops.textContent = String(s.drops);
    e.rtt.textContent = s.rttMs === null ? "–" : s.rttMs.toFixed(1);
  }
}
