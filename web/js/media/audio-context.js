//! The page's single WebAudio context, shared by microphone capture and speech playback.
//
// Browsers start a context "suspended" until the user interacts with the page; kiosk mode runs Chromium with
// `--autoplay-policy=no-user-gesture-required`, otherwise the first click resumes it.

let context = null;

export function audioContext() {
  if (!context) {
    context = new AudioContext({ latencyHint: "interactive" });
    const resume = () => {
      if (context.state === "suspended") context.resume().catch(() => {});
    };
    window.addEventListener("pointerdown", resume);
    window.addEventListener("keydown", resume);
  }
  if (context.state === "suspended") context.resume().catch(() => {});
  return context;
}

/** The audio clock in seconds; before any context exists, the page clock stands in. */
export function audioClock() {
  return context ? context.currentTime : performance.now() / 1000;
}
