// @ts-check
//! The viseme set the page understands (the 15 Oculus visemes) and the mouth shape each one makes.
//
// A shape is a set of mouth parameters for `face.js`: `jaw` (0 closed .. 1 wide open), `mouthWidth` (relative to
// rest), `round` (lip rounding / protrusion), `teeth` and `tongue` visibility, `lipPress` (lips pressed together).

const SHAPES = {
  sil: { jaw: 0.0, mouthWidth: 1.0, round: 0.0, teeth: 0.6, tongue: 0.0, lipPress: 0.0 },
  PP: { jaw: 0.0, mouthWidth: 0.94, round: 0.1, teeth: 0.0, tongue: 0.0, lipPress: 1.0 },
  FF: { jaw: 0.1, mouthWidth: 1.0, round: 0.0, teeth: 1.0, tongue: 0.0, lipPress: 0.4 },
  TH: { jaw: 0.2, mouthWidth: 1.0, round: 0.0, teeth: 0.8, tongue: 1.0, lipPress: 0.0 },
  DD: { jaw: 0.25, mouthWidth: 1.02, round: 0.0, teeth: 0.8, tongue: 0.6, lipPress: 0.0 },
  kk: { jaw: 0.32, mouthWidth: 1.0, round: 0.0, teeth: 0.5, tongue: 0.3, lipPress: 0.0 },
  CH: { jaw: 0.22, mouthWidth: 0.84, round: 0.45, teeth: 1.0, tongue: 0.0, lipPress: 0.0 },
  SS: { jaw: 0.1, mouthWidth: 1.06, round: 0.0, teeth: 1.0, tongue: 0.0, lipPress: 0.0 },
  nn: { jaw: 0.2, mouthWidth: 1.0, round: 0.0, teeth: 0.6, tongue: 0.8, lipPress: 0.0 },
  RR: { jaw: 0.22, mouthWidth: 0.86, round: 0.5, teeth: 0.4, tongue: 0.2, lipPress: 0.0 },
  aa: { jaw: 0.85, mouthWidth: 1.05, round: 0.0, teeth: 0.4, tongue: 0.3, lipPress: 0.0 },
  E: { jaw: 0.5, mouthWidth: 1.14, round: 0.0, teeth: 0.8, tongue: 0.2, lipPress: 0.0 },
  I: { jaw: 0.3, mouthWidth: 1.2, round: 0.0, teeth: 0.9, tongue: 0.1, lipPress: 0.0 },
  O: { jaw: 0.6, mouthWidth: 0.82, round: 0.75, teeth: 0.2, tongue: 0.2, lipPress: 0.0 },
  U: { jaw: 0.3, mouthWidth: 0.72, round: 1.0, teeth: 0.0, tongue: 0.0, lipPress: 0.0 },
};

export const VISEMES = Object.freeze(Object.keys(SHAPES));

/** The mouth shape of viseme `name`, or of silence for a name outside the set. */
export function mouthShape(name) {
  return SHAPES[name] ?? SHAPES.sil;
}
