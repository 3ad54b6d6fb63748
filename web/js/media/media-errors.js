// @ts-check
//! Turns getUserMedia failures into messages a user can act on.

export function explainMediaError(err, device) {
  const name = err && err.name;
  switch (name) {
    case "NotAllowedError":
    case "SecurityError":
      return `Permission to use the ${device} was denied. Allow it in the browser's site settings, then press Start again.`;
    case "NotFoundError":
    case "OverconstrainedError":
      return `No ${device} was found. Connect one and press Start again.`;
    case "NotReadableError":
    case "AbortError":
      return `The ${device} is busy or failed to start (another application may be using it).`;
    default:
      return `The ${device} could not be started: ${err && err.message ? err.message : String(err)}`;
  }
}
