// @ts-check
/**
 * @file The server's clock as seen from the page, from the link's ping/pong: each pong carries the server's time
 * (ms since the Unix epoch), and the page's send and receive times bracket it, so the offset is known to within
 * half the round trip. The sample with the shortest round trip among the recent ones wins (as NTP filters).
 */

/** How many recent samples the estimate is chosen from (one ping every few seconds: about a minute's worth). */
const KEEP = 16;

export class ServerClock {
  constructor() {
    /** @type {{rtt: number, offset: number}[]} */
    this.samples = [];
  }

  /**
   * One ping's answer: sent and received on the page's epoch clock (ms), `serverMs` stamped by the server between.
   * @param {number} sentMs
   * @param {number} receivedMs
   * @param {number} serverMs
   */
  sample(sentMs, receivedMs, serverMs) {
    const rtt = receivedMs - sentMs;
    if (!(rtt >= 0) || !Number.isFinite(serverMs)) return;
    this.samples.push({ rtt, offset: serverMs - (sentMs + receivedMs) / 2 });
    if (this.samples.length > KEEP) this.samples.shift();
  }

  /** Server time minus page time (ms), or null before the first pong. @returns {number | null} */
  offset() {
    if (this.samples.length === 0) return null;
    return this.samples.reduce((best, s) => (s.rtt < best.rtt ? s : best)).offset;
  }

  /**
   * A server time (ms since the epoch) on the page's epoch clock, or null while the offset is unknown.
   * @param {number} serverMs
   * @returns {number | null}
   */
  toPage(serverMs) {
    const o = this.offset();
    return o === null ? null : serverMs - o;
  }
}
