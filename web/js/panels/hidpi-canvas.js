//! Keeps a canvas's backing store matched to its on-screen size and the device pixel ratio, so drawing is sharp.

/**
 * Watches `canvas` and calls `onSize(width, height)` (CSS pixels) whenever it changes size, after resizing the
 * backing store and scaling the 2D context so callers draw in CSS pixels.
 */
export function trackCanvasSize(canvas, ctx, onSize) {
  const fit = () => {
    const dpr = window.devicePixelRatio || 1;
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    if (w === 0 || h === 0) return;
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    onSize(w, h);
  };
  new ResizeObserver(fit).observe(canvas);
  fit();
}
