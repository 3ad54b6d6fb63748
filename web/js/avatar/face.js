//! Draws the avatar's face on a 2D canvas from one pose (head turn, eye direction, eyelids, brows, mouth).
//
// Everything is drawn in a virtual 1000 x 1000 space centred on the stage, so the look does not depend on the
// window size. The face is flat-shaded with soft gradients; a head turn is faked with parallax (features move
// more than the outline, the nose most), which reads as 3D without a 3D engine.

const SKIN = { light: "#f7d3b7", mid: "#eab593", dark: "#c98b6b", shadow: "rgba(120, 60, 40, 0.28)" };
const HAIR = { base: "#2b1d2a", mid: "#45293d", shine: "rgba(190, 140, 170, 0.35)" };
const IRIS = { outer: "#1d5e68", inner: "#49b3b0", ring: "#0f3238" };
const LIP = { upper: "#b9566a", lower: "#cf6d7d", line: "#7c2f41" };
const CLOTH = { base: "#1c2b44", light: "#2b4266", collar: "#5fd4c4" };

/** A neutral pose; the animator produces these every frame. */
export function restPose() {
  return {
    yaw: 0, pitch: 0, roll: 0, // head, -1..1 (roll in radians * 0.2 scale)
    eyeX: 0, eyeY: 0, // eye direction, -1..1 (positive x: towards the viewer's right)
    lid: 1, // eyelid openness 0..1 (after squint)
    browRaise: 0, browInner: 0, // -1..1
    jaw: 0, mouthWidth: 1, round: 0, smile: 0.15, teeth: 0.6, tongue: 0, lipPress: 0,
    blush: 0.25,
    breath: 0,
  };
}

/** Draws `pose` onto `ctx` filling a `width` x `height` area (CSS pixels, the transform already holds the DPR). */
export function drawFace(ctx, width, height, pose) {
  ctx.clearRect(0, 0, width, height);
  const scale = Math.min(width / 1000, height / 1000) * 1.02;
  ctx.save();
  ctx.translate(width / 2, height / 2 + 20 * scale);
  ctx.scale(scale, scale);
  ctx.translate(-500, -500);

  drawShoulders(ctx, pose);
  // The head rotates around the neck so a tilt looks natural.
  ctx.save();
  ctx.translate(500, 760);
  ctx.rotate(pose.roll);
  ctx.translate(-500, -760 + pose.breath * 3);
  drawBackHair(ctx, pose);
  drawNeck(ctx, pose);
  drawEars(ctx, pose);
  drawHead(ctx, pose);
  drawCheeks(ctx, pose);
  drawEyes(ctx, pose);
  drawBrows(ctx, pose);
  drawNose(ctx, pose);
  drawMouth(ctx, pose);
  drawFringe(ctx, pose);
  ctx.restore();
  ctx.restore();
}

function lerp(a, b, t) {
  return a + (b - a) * t;
}

/** Horizontal parallax of a feature at `depth` (0 = the skull outline, 1 = the nose tip). */
function px(pose, depth) {
  return pose.yaw * (14 + 42 * depth);
}

function py(pose, depth) {
  return pose.pitch * (10 + 26 * depth);
}

function drawShoulders(ctx, pose) {
  const sx = pose.yaw * 6;
  const g = ctx.createLinearGradient(0, 820, 0, 1000);
  g.addColorStop(0, CLOTH.light);
  g.addColorStop(1, CLOTH.base);
  ctx.fillStyle = g;
  ctx.beginPath();
  ctx.moveTo(150 + sx, 1010);
  ctx.bezierCurveTo(170 + sx, 900, 260 + sx, 850, 400 + sx, 830);
  ctx.lineTo(600 + sx, 830);
  ctx.bezierCurveTo(740 + sx, 850, 830 + sx, 900, 850 + sx, 1010);
  ctx.closePath();
  ctx.fill();
  // Collar: a thin accent line that gives the agent a bit of identity.
  ctx.strokeStyle = CLOTH.collar;
  ctx.lineWidth = 5;
  ctx.lineCap = "round";
  ctx.beginPath();
  ctx.moveTo(420 + sx, 835);
  ctx.quadraticCurveTo(500 + sx, 905, 580 + sx, 835);
  ctx.stroke();
}

function drawNeck(ctx, pose) {
  const sx = pose.yaw * 8;
  const g = ctx.createLinearGradient(430, 0, 570, 0);
  g.addColorStop(0, SKIN.dark);
  g.addColorStop(0.5, SKIN.mid);
  g.addColorStop(1, SKIN.dark);
  ctx.fillStyle = g;
  ctx.beginPath();
  ctx.moveTo(440 + sx, 660);
  ctx.lineTo(438 + sx, 800);
  ctx.quadraticCurveTo(500 + sx, 860, 562 + sx, 800);
  ctx.lineTo(560 + sx, 660);
  ctx.closePath();
  ctx.fill();
  // Shadow under the chin.
  const s = ctx.createLinearGradient(0, 700, 0, 770);
  s.addColorStop(0, "rgba(110, 55, 40, 0.45)");
  s.addColorStop(1, "rgba(110, 55, 40, 0)");
  ctx.fillStyle = s;
  ctx.fillRect(430 + sx, 690, 140, 80);
}

function drawBackHair(ctx, pose) {
  const sx = -pose.yaw * 10;
  const g = ctx.createLinearGradient(0, 160, 0, 820);
  g.addColorStop(0, HAIR.mid);
  g.addColorStop(1, HAIR.base);
  ctx.fillStyle = g;
  ctx.beginPath();
  ctx.moveTo(500 + sx, 150);
  ctx.bezierCurveTo(700 + sx, 150, 770 + sx, 300, 765 + sx, 470);
  ctx.bezierCurveTo(762 + sx, 600, 790 + sx, 700, 740 + sx, 780);
  ctx.bezierCurveTo(700 + sx, 820, 620 + sx, 800, 600 + sx, 760);
  ctx.lineTo(400 + sx, 760);
  ctx.bezierCurveTo(380 + sx, 800, 300 + sx, 820, 260 + sx, 780);
  ctx.bezierCurveTo(210 + sx, 700, 238 + sx, 600, 235 + sx, 470);
  ctx.bezierCurveTo(230 + sx, 300, 300 + sx, 150, 500 + sx, 150);
  ctx.closePath();
  ctx.fill();
}

function drawEars(ctx, pose) {
  const sx = pose.yaw * 10;
  for (const side of [-1, 1]) {
    // The ear on the side the head turns away from hides behind the cheek.
    const hide = Math.max(0, side * pose.yaw);
    const x = 500 + side * (205 - hide * 25) + sx;
    ctx.fillStyle = SKIN.mid;
    ctx.beginPath();
    ctx.ellipse(x, 505, 26 - hide * 12, 48, side * 0.12, 0, Math.PI * 2);
    ctx.fill();
    ctx.fillStyle = "rgba(160, 80, 60, 0.35)";
    ctx.beginPath();
    ctx.ellipse(x + side * 4, 505, 12 - hide * 6, 28, side * 0.12, 0, Math.PI * 2);
    ctx.fill();
  }
}

function headPath(ctx, pose) {
  const sx = px(pose, 0);
  const sy = py(pose, 0) * 0.5;
  // Chin follows the turn a little more than the skull: it is further forward.
  const cx = pose.yaw * 22;
  ctx.beginPath();
  ctx.moveTo(500 + sx, 215 + sy);
  ctx.bezierCurveTo(625 + sx, 215 + sy, 712 + sx, 300 + sy, 712 + sx, 440 + sy);
  ctx.bezierCurveTo(712 + sx, 560 + sy, 680 + cx, 640 + sy, 610 + cx, 700 + sy);
  ctx.bezierCurveTo(570 + cx, 735 + sy, 540 + cx, 748 + sy, 500 + cx, 748 + sy);
  ctx.bezierCurveTo(460 + cx, 748 + sy, 430 + cx, 735 + sy, 390 + cx, 700 + sy);
  ctx.bezierCurveTo(320 + cx, 640 + sy, 288 + sx, 560 + sy, 288 + sx, 440 + sy);
  ctx.bezierCurveTo(288 + sx, 300 + sy, 375 + sx, 215 + sy, 500 + sx, 215 + sy);
  ctx.closePath();
}

function drawHead(ctx, pose) {
  const lightX = 470 + pose.yaw * 40;
  const g = ctx.createRadialGradient(lightX, 420, 40, 500, 480, 330);
  g.addColorStop(0, SKIN.light);
  g.addColorStop(0.6, SKIN.mid);
  g.addColorStop(1, SKIN.dark);
  headPath(ctx, pose);
  ctx.fillStyle = g;
  ctx.fill();
  // Side shading on the far cheek makes the turn readable.
  ctx.save();
  headPath(ctx, pose);
  ctx.clip();
  const side = pose.yaw >= 0 ? -1 : 1;
  const amount = 0.12 + Math.abs(pose.yaw) * 0.25;
  const sg = ctx.createLinearGradient(500 + side * 220, 0, 500 + side * 80, 0);
  sg.addColorStop(0, `rgba(150, 75, 55, ${amount})`);
  sg.addColorStop(1, "rgba(150, 75, 55, 0)");
  ctx.fillStyle = sg;
  ctx.fillRect(250, 200, 500, 560);
  ctx.restore();
}

function drawCheeks(ctx, pose) {
  const a = 0.18 + pose.blush * 0.3;
  for (const side of [-1, 1]) {
    const x = 500 + side * 125 + px(pose, 0.55);
    const y = 575 + py(pose, 0.55);
    const g = ctx.createRadialGradient(x, y, 4, x, y, 62);
    g.addColorStop(0, `rgba(235, 110, 120, ${a})`);
    g.addColorStop(1, "rgba(235, 110, 120, 0)");
    ctx.fillStyle = g;
    ctx.beginPath();
    ctx.arc(x, y, 62, 0, Math.PI * 2);
    ctx.fill();
  }
}

/** The almond outline of one eye; `openness` moves the upper edge from the top (1) to the lower edge (0). */
function eyeShape(cx, cy, w, side) {
  const inner = { x: cx - side * w * 0.5, y: cy + 4 };
  const outer = { x: cx + side * w * 0.5, y: cy - 3 };
  return { inner, outer, topY: cy - 52, bottomY: cy + 34 };
}

function drawEyes(ctx, pose) {
  for (const side of [-1, 1]) {
    // The eye on the far side of a turn looks narrower.
    const far = Math.max(0, -side * pose.yaw);
    const w = 118 * (1 - far * 0.22);
    const cx = 500 + side * 98 + px(pose, 0.5) + side * pose.yaw * 6;
    const cy = 478 + py(pose, 0.5);
    drawEye(ctx, pose, cx, cy, w, side);
  }
}

function drawEye(ctx, pose, cx, cy, w, side) {
  const e = eyeShape(cx, cy, w, side);
  const lidY = lerp(e.bottomY, e.topY, pose.lid);
  const c1x = lerp(e.inner.x, e.outer.x, 0.25);
  const c2x = lerp(e.inner.x, e.outer.x, 0.7);

  // Socket shadow, so the eye sits in the face rather than on it.
  const sg = ctx.createRadialGradient(cx, cy - 8, 20, cx, cy - 8, 90);
  sg.addColorStop(0, "rgba(150, 80, 70, 0.13)");
  sg.addColorStop(1, "rgba(150, 80, 70, 0)");
  ctx.fillStyle = sg;
  ctx.beginPath();
  ctx.ellipse(cx, cy - 8, 92, 66, 0, 0, Math.PI * 2);
  ctx.fill();

  // The visible opening: between the lid line and the lower edge.
  ctx.save();
  ctx.beginPath();
  ctx.moveTo(e.inner.x, e.inner.y);
  ctx.bezierCurveTo(c1x, lidY, c2x, lidY, e.outer.x, e.outer.y);
  ctx.bezierCurveTo(c2x, e.bottomY, c1x, e.bottomY, e.inner.x, e.inner.y);
  ctx.closePath();
  ctx.clip();

  const white = ctx.createRadialGradient(cx, cy, 10, cx, cy, 70);
  white.addColorStop(0, "#ffffff");
  white.addColorStop(1, "#dfe3ea");
  ctx.fillStyle = white;
  ctx.fillRect(cx - 80, cy - 70, 160, 140);

  const ix = cx + pose.eyeX * w * 0.26;
  const iy = cy - 6 + pose.eyeY * 14;
  const r = 31;
  const ig = ctx.createRadialGradient(ix, iy, 4, ix, iy, r);
  ig.addColorStop(0, IRIS.inner);
  ig.addColorStop(0.75, IRIS.outer);
  ig.addColorStop(1, IRIS.ring);
  ctx.fillStyle = ig;
  ctx.beginPath();
  ctx.arc(ix, iy, r, 0, Math.PI * 2);
  ctx.fill();
  ctx.fillStyle = "#0b1114";
  ctx.beginPath();
  ctx.arc(ix, iy, 13, 0, Math.PI * 2);
  ctx.fill();
  ctx.fillStyle = "rgba(255, 255, 255, 0.92)";
  ctx.beginPath();
  ctx.arc(ix - 10, iy - 11, 7.5, 0, Math.PI * 2);
  ctx.fill();
  ctx.fillStyle = "rgba(255, 255, 255, 0.5)";
  ctx.beginPath();
  ctx.arc(ix + 9, iy + 9, 3.5, 0, Math.PI * 2);
  ctx.fill();
  // The upper lid casts a soft shadow on the eyeball.
  const shadow = ctx.createLinearGradient(0, lidY, 0, lidY + 26);
  shadow.addColorStop(0, "rgba(60, 30, 30, 0.35)");
  shadow.addColorStop(1, "rgba(60, 30, 30, 0)");
  ctx.fillStyle = shadow;
  ctx.fillRect(cx - 80, lidY - 2, 160, 30);
  ctx.restore();

  // Upper lid edge with lashes: thicker towards the outer corner.
  ctx.strokeStyle = "#2a1a22";
  ctx.lineCap = "round";
  ctx.lineWidth = 6;
  ctx.beginPath();
  ctx.moveTo(e.inner.x, e.inner.y);
  ctx.bezierCurveTo(c1x, lidY, c2x, lidY, e.outer.x, e.outer.y);
  ctx.stroke();
  ctx.lineWidth = 4;
  ctx.beginPath();
  const flick = lerp(8, 3, 1 - pose.lid);
  ctx.moveTo(e.outer.x - side * 4, e.outer.y);
  ctx.quadraticCurveTo(e.outer.x + side * 10, e.outer.y - flick, e.outer.x + side * 18, e.outer.y - flick - 6);
  ctx.stroke();

  // Crease above the lid: follows the lid a little, gives it volume.
  const creaseY = lerp(e.topY - 6, e.topY - 16, pose.lid) - pose.browRaise * 4;
  ctx.strokeStyle = "rgba(140, 75, 60, 0.45)";
  ctx.lineWidth = 3;
  ctx.beginPath();
  ctx.moveTo(lerp(e.inner.x, e.outer.x, 0.08), e.inner.y - 12);
  ctx.bezierCurveTo(c1x, creaseY, c2x, creaseY, lerp(e.inner.x, e.outer.x, 0.95), e.outer.y - 14);
  ctx.stroke();

  // Lower lid: a faint line.
  ctx.strokeStyle = "rgba(140, 75, 60, 0.35)";
  ctx.lineWidth = 2.5;
  ctx.beginPath();
  ctx.moveTo(lerp(e.inner.x, e.outer.x, 0.12), e.inner.y + 4);
  ctx.bezierCurveTo(c1x, e.bottomY + 3, c2x, e.bottomY + 3, lerp(e.inner.x, e.outer.x, 0.9), e.outer.y + 5);
  ctx.stroke();
}

function drawBrows(ctx, pose) {
  for (const side of [-1, 1]) {
    const cx = 500 + side * 100 + px(pose, 0.45) + side * pose.yaw * 4;
    const base = 388 + py(pose, 0.45) - pose.browRaise * 22;
    // browInner > 0 lifts the inner ends (sad, worried); < 0 pulls them down (angry, focused).
    const innerY = base + 8 - pose.browInner * 18;
    const outerY = base + 12 + pose.browInner * 6;
    const peakY = base - 12 - pose.browRaise * 6;
    const ix = cx - side * 60;
    const ox = cx + side * 68;
    const g = ctx.createLinearGradient(ix, 0, ox, 0);
    g.addColorStop(0, "#4a2f3b");
    g.addColorStop(0.4, "#35212c");
    g.addColorStop(1, "#2a1a22");
    ctx.fillStyle = g;
    // A tapered shape: thick and square at the inner end, thin at the tail.
    ctx.beginPath();
    ctx.moveTo(ix, innerY + 8);
    ctx.quadraticCurveTo(cx + side * 6, peakY + 8, ox, outerY + 1);
    ctx.quadraticCurveTo(cx + side * 10, peakY - 12, ix + side * 4, innerY - 9);
    ctx.quadraticCurveTo(ix - side * 4, innerY, ix, innerY + 8);
    ctx.closePath();
    ctx.fill();
  }
}

function drawNose(ctx, pose) {
  const x = 500 + px(pose, 1);
  const y = 580 + py(pose, 1);
  // Bridge: a soft shadow line on the side away from the light.
  ctx.strokeStyle = "rgba(150, 80, 60, 0.22)";
  ctx.lineWidth = 5;
  ctx.lineCap = "round";
  ctx.beginPath();
  ctx.moveTo(x - 16 - pose.yaw * 6, 535);
  ctx.quadraticCurveTo(x - 22 - pose.yaw * 4, 565, x - 20, y - 8);
  ctx.stroke();
  // Tip highlight and nostrils.
  const g = ctx.createRadialGradient(x - 4, y - 8, 2, x, y - 4, 26);
  g.addColorStop(0, "rgba(255, 235, 220, 0.7)");
  g.addColorStop(1, "rgba(255, 235, 220, 0)");
  ctx.fillStyle = g;
  ctx.beginPath();
  ctx.arc(x, y - 4, 26, 0, Math.PI * 2);
  ctx.fill();
  ctx.strokeStyle = "rgba(130, 60, 45, 0.55)";
  ctx.lineWidth = 4;
  ctx.beginPath();
  ctx.moveTo(x - 24, y + 2);
  ctx.quadraticCurveTo(x - 12, y + 12, x - 4, y + 8);
  ctx.moveTo(x + 4, y + 8);
  ctx.quadraticCurveTo(x + 12, y + 12, x + 24, y + 2);
  ctx.stroke();
}

function drawMouth(ctx, pose) {
  const cx = 500 + px(pose, 0.8);
  const cy = 655 + py(pose, 0.8);
  const half = 64 * pose.mouthWidth * (1 - pose.round * 0.38);
  const open = pose.jaw * 58 * (1 + pose.round * 0.15);
  const smileLift = pose.smile * 17;
  const lipT = 14 + pose.round * 6 - pose.lipPress * 5; // lip thickness
  const left = { x: cx - half, y: cy - smileLift };
  const right = { x: cx + half, y: cy - smileLift };
  const innerTop = cy - open * 0.18;
  const innerBottom = cy + open * 0.82;
  const roundness = pose.round;

  // Inner mouth first: dark cavity, teeth at the top, tongue at the bottom.
  if (open > 1.5) {
    ctx.save();
    ctx.beginPath();
    ctx.moveTo(left.x + 4, left.y);
    ctx.bezierCurveTo(cx - half * 0.5, innerTop - 4, cx + half * 0.5, innerTop - 4, right.x - 4, right.y);
    ctx.bezierCurveTo(
      cx + half * (0.55 + roundness * 0.3), innerBottom, cx - half * (0.55 + roundness * 0.3), innerBottom,
      left.x + 4, left.y,
    );
    ctx.closePath();
    ctx.fillStyle = "#4a1420";
    ctx.fill();
    ctx.clip();
    if (pose.teeth > 0) {
      ctx.fillStyle = "#f4f1ee";
      ctx.fillRect(cx - half, innerTop - 6, half * 2, 10 + 8 * pose.teeth);
    }
    const tongueY = innerBottom - 6 + (1 - pose.tongue) * 6;
    ctx.fillStyle = "#c9566a";
    ctx.beginPath();
    ctx.ellipse(cx, tongueY, half * 0.6, 12 + open * 0.15, 0, 0, Math.PI * 2);
    ctx.fill();
    ctx.restore();
  }

  // Upper lip with a cupid's bow.
  const ug = ctx.createLinearGradient(0, cy - 22, 0, cy + 4);
  ug.addColorStop(0, LIP.upper);
  ug.addColorStop(1, "#9c4257");
  ctx.fillStyle = ug;
  ctx.beginPath();
  ctx.moveTo(left.x, left.y);
  ctx.bezierCurveTo(cx - half * 0.6, cy - lipT - 6, cx - half * 0.25, cy - lipT - 8, cx, cy - lipT + 1);
  ctx.bezierCurveTo(cx + half * 0.25, cy - lipT - 8, cx + half * 0.6, cy - lipT - 6, right.x, right.y);
  ctx.bezierCurveTo(cx + half * 0.5, innerTop - 2, cx - half * 0.5, innerTop - 2, left.x, left.y);
  ctx.closePath();
  ctx.fill();

  // Lower lip: fuller, with a highlight.
  const lowerBottom = innerBottom + lipT + 5;
  const lg = ctx.createLinearGradient(0, innerBottom - 2, 0, lowerBottom);
  lg.addColorStop(0, LIP.lower);
  lg.addColorStop(1, "#a94a5e");
  ctx.fillStyle = lg;
  ctx.beginPath();
  ctx.moveTo(left.x, left.y);
  ctx.bezierCurveTo(
    cx - half * (0.55 + roundness * 0.3), innerBottom + 1, cx + half * (0.55 + roundness * 0.3), innerBottom + 1,
    right.x, right.y,
  );
  ctx.bezierCurveTo(cx + half * 0.6, lowerBottom, cx - half * 0.6, lowerBottom, left.x, left.y);
  ctx.closePath();
  ctx.fill();
  ctx.fillStyle = "rgba(255, 220, 225, 0.35)";
  ctx.beginPath();
  ctx.ellipse(cx - 6, innerBottom + lipT * 0.6, half * 0.28, 3.5, 0, 0, Math.PI * 2);
  ctx.fill();

  // The line where the lips meet when the mouth is closed, and the corners.
  ctx.strokeStyle = LIP.line;
  ctx.lineWidth = 2.5;
  ctx.lineCap = "round";
  if (open <= 1.5) {
    ctx.beginPath();
    ctx.moveTo(left.x, left.y);
    ctx.bezierCurveTo(cx - half * 0.5, cy + 2, cx + half * 0.5, cy + 2, right.x, right.y);
    ctx.stroke();
  }
  ctx.strokeStyle = "rgba(140, 70, 60, 0.45)";
  for (const s of [-1, 1]) {
    const c = s < 0 ? left : right;
    ctx.beginPath();
    ctx.moveTo(c.x + s * 1, c.y);
    ctx.quadraticCurveTo(c.x + s * 7, c.y - 2 - pose.smile * 4, c.x + s * 9, c.y - 6 - pose.smile * 6);
    ctx.stroke();
  }
}

function drawFringe(ctx, pose) {
  const sx = px(pose, 0.1);
  const sy = py(pose, 0) * 0.5;
  const g = ctx.createLinearGradient(0, 150, 0, 420);
  g.addColorStop(0, HAIR.mid);
  g.addColorStop(1, HAIR.base);
  ctx.fillStyle = g;
  ctx.save();
  ctx.translate(sx, sy);
  ctx.beginPath();
  ctx.moveTo(282, 480);
  ctx.bezierCurveTo(262, 300, 340, 176, 505, 170);
  ctx.bezierCurveTo(660, 168, 742, 280, 722, 480);
  ctx.bezierCurveTo(714, 410, 700, 360, 672, 318);
  // A side-swept fringe: a few locks with pointed tips, from the right temple to the left.
  ctx.quadraticCurveTo(650, 330, 628, 332);
  ctx.quadraticCurveTo(610, 310, 590, 300);
  ctx.quadraticCurveTo(560, 330, 520, 340);
  ctx.quadraticCurveTo(500, 315, 470, 300);
  ctx.quadraticCurveTo(430, 330, 392, 338);
  ctx.quadraticCurveTo(385, 312, 372, 296);
  ctx.bezierCurveTo(330, 330, 300, 390, 282, 480);
  ctx.closePath();
  ctx.fill();
  // Strand lines and a soft shine band.
  ctx.strokeStyle = "rgba(15, 8, 14, 0.35)";
  ctx.lineWidth = 3;
  ctx.lineCap = "round";
  ctx.beginPath();
  ctx.moveTo(640, 220);
  ctx.quadraticCurveTo(600, 280, 522, 330);
  ctx.moveTo(560, 205);
  ctx.quadraticCurveTo(520, 260, 430, 315);
  ctx.moveTo(680, 260);
  ctx.quadraticCurveTo(660, 300, 628, 326);
  ctx.stroke();
  ctx.strokeStyle = HAIR.shine;
  ctx.lineWidth = 14;
  ctx.beginPath();
  ctx.moveTo(380, 236);
  ctx.quadraticCurveTo(470, 196, 590, 212);
  ctx.stroke();
  ctx.restore();
}
