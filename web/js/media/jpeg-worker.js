//! Web worker: turns camera frames into 640x360 JPEGs off the page's main thread (which is busy drawing the avatar).
//
// Two ways in:
// - `{type: "stream", readable, fps, quality, width, height}`: the camera track's frames as a ReadableStream
//   (MediaStreamTrackProcessor). The worker paces itself on the camera's own frames, so a busy main thread cannot
//   slow the camera down; it keeps one frame in `fps` and encodes it.
// - `{type: "bitmap", bitmap, quality}`: one already scaled ImageBitmap (browsers without track processors).
// `{type: "fps", fps}` changes the pace. Answers are `{jpeg, capturedAt}` (an ArrayBuffer, and when the frame was
// taken, ms since the epoch: the start of the "camera capture -> box drawn" latency) or `{error}`.

let canvas = null;
let ctx = null;
let fps = 15;

function surface(width, height) {
  if (!canvas || canvas.width !== width || canvas.height !== height) {
    canvas = new OffscreenCanvas(width, height);
    ctx = canvas.getContext("2d", { alpha: false });
  }
  return ctx;
}

async function encode(quality, capturedAt) {
  const blob = await canvas.convertToBlob({ type: "image/jpeg", quality });
  const jpeg = await blob.arrayBuffer();
  self.postMessage({ jpeg, capturedAt }, [jpeg]);
}

/** Draws `frame` scaled to cover width x height (centre crop), like the preview's object-fit: cover. */
function drawCover(frame, width, height) {
  const fw = frame.displayWidth;
  const fh = frame.displayHeight;
  const scale = Math.max(width / fw, height / fh);
  const sw = width / scale;
  const sh = height / scale;
  surface(width, height).drawImage(frame, (fw - sw) / 2, (fh - sh) / 2, sw, sh, 0, 0, width, height);
}

async function pump({ readable, quality, width, height }) {
  const reader = readable.getReader();
  let next = 0;
  for (;;) {
    const { value: frame, done } = await reader.read();
    if (done) return;
    const now = performance.now();
    const interval = 1000 / fps;
    // Accept a frame a little early (camera jitter), else a 15 fps camera at 15 fps would lose every other one.
    if (now + interval / 4 < next) {
      frame.close();
      continue;
    }
    next = Math.max(next + interval, now - interval / 2);
    const capturedAt = performance.timeOrigin + now;
    try {
      drawCover(frame, width, height);
      frame.close();
      await encode(quality, capturedAt);
    } catch (err) {
      frame.close();
      self.postMessage({ error: String(err && err.message ? err.message : err) });
    }
  }
}

self.onmessage = async (ev) => {
  const msg = ev.data;
  if (msg.type === "fps") {
    if (Number.isFinite(msg.fps) && msg.fps > 0) fps = msg.fps;
  } else if (msg.type === "stream") {
    fps = msg.fps;
    pump(msg).catch((err) => self.postMessage({ error: String(err) }));
  } else if (msg.type === "bitmap") {
    try {
      surface(msg.bitmap.width, msg.bitmap.height).drawImage(msg.bitmap, 0, 0);
      msg.bitmap.close();
      await encode(msg.quality, msg.capturedAt);
    } catch (err) {
      self.postMessage({ error: String(err && err.message ? err.message : err) });
    }
  }
};
