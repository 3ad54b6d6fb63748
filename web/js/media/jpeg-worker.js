//! Web worker: encodes camera frames to JPEG off the page's main thread (which is busy drawing the avatar).
//
// Each message carries an ImageBitmap already scaled to the frame size; the answer carries the JPEG bytes, or an
// error text. The canvas is drawn synchronously before the asynchronous encode, so frames never mix.

let canvas = null;
let ctx = null;

self.onmessage = async (ev) => {
  const { bitmap, quality } = ev.data;
  try {
    if (!canvas || canvas.width !== bitmap.width || canvas.height !== bitmap.height) {
      canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
      ctx = canvas.getContext("2d", { alpha: false });
    }
    ctx.drawImage(bitmap, 0, 0);
    bitmap.close();
    const blob = await canvas.convertToBlob({ type: "image/jpeg", quality });
    const jpeg = await blob.arrayBuffer();
    self.postMessage({ jpeg }, [jpeg]);
  } catch (err) {
    self.postMessage({ error: String(err && err.message ? err.message : err) });
  }
};
