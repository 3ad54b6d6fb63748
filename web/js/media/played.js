// @ts-check
/**
 * @file When the user hears an utterance begin, on the server's clock: the page tells the server (`{"type":
 * "played"}`, published on `Agent.playback`) so that a turn's trace ends where the user hears the reply
 * (docs/telemetry.md). An utterance's sample 0 enters the playback route at its anchor on the audio clock and is
 * heard the route's delay later; the audio clock is put on the page's epoch clock through the moment both are read,
 * and that on the server's through the link's ping/pong offset.
 */

/**
 * The `played` message for `utterance`, or null while the server's clock is unknown.
 * @param {number} utterance the number its speech chunks carry
 * @param {number} anchorS audio-clock time its sample 0 enters the route
 * @param {number} delayS how far behind the audio clock the route plays
 * @param {number} audioNowS the audio clock now
 * @param {number} pageNowMs the page's epoch clock now (ms)
 * @param {number | null} offsetMs server time minus page time (ms), null before the first pong
 * @returns {{type: "played", utterance: number, at_ms: number} | null}
 */
export function playedMessage(utterance, anchorS, delayS, audioNowS, pageNowMs, offsetMs) {
  if (offsetMs === null || !Number.isFinite(offsetMs) || !(utterance > 0)) return null;
  const heardPageMs = pageNowMs + (anchorS + delayS - audioNowS) * 1000;
  if (!Number.isFinite(heardPageMs)) return null;
  return { type: "played", utterance, at_ms: heardPageMs + offsetMs };
}
