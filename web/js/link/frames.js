// @ts-check
//! Binary frame layout of the browser link (docs/browser-link.md, section 2): an 8-byte header, then the payload.

export const KIND = Object.freeze({
  AUDIO: 0x01,
  VIDEO: 0x02,
  SPEECH: 0x81,
  SPECTRUM: 0x82,
});

const VERSION = 1;
export const HEADER_BYTES = 8;

/** Builds one frame: header (`kind`, version, reserved, `seq`) followed by `payload` (an ArrayBuffer or view). */
export function encodeFrame(kind, seq, payload) {
  const body = payload instanceof ArrayBuffer ? new Uint8Array(payload) : new Uint8Array(payload.buffer, payload.byteOffset, payload.byteLength);
  const out = new Uint8Array(HEADER_BYTES + body.byteLength);
  const view = new DataView(out.buffer);
  view.setUint8(0, kind);
  view.setUint8(1, VERSION);
  view.setUint16(2, 0, true);
  view.setUint32(4, seq >>> 0, true);
  out.set(body, HEADER_BYTES);
  return out.buffer;
}

/** Splits a received frame; returns null for one that is too short or of another version. */
export function decodeFrame(buffer) {
  if (buffer.byteLength < HEADER_BYTES) return null;
  const view = new DataView(buffer);
  if (view.getUint8(1) !== VERSION) return null;
  return {
    kind: view.getUint8(0),
    seq: view.getUint32(4, true),
    body: buffer.slice(HEADER_BYTES),
  };
}

/** Speech frames carry the utterance id and the first sample's offset before the PCM. */
export function decodeSpeech(body) {
  if (body.byteLength < 8) return null;
  const view = new DataView(body);
  const pcmBytes = body.byteLength - 8;
  return {
    utterance: view.getUint32(0, true),
    offset: view.getUint32(4, true),
    pcm: new Int16Array(body.slice(8, 8 + pcmBytes - (pcmBytes % 2))),
  };
}
