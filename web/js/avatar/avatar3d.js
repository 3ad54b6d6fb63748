//! The 3D avatar: the generated head (assets/avatar.glb, or avatar-lite.glb on software WebGL) rendered with three.js, driven like the 2D face.
//
// Same commands and debug fields as avatar.js (blink, lookAt, setMood, scheduleVisemes, stopSpeech,
// debugState), and the same controllers (blink.js, gaze.js, moods.js), so both renderers behave alike and the
// same tests run against either. What differs: visemes are morph targets blended by viseme-mix.js on the audio
// clock, eyes are meshes that rotate, and the head turns on the neck (rig3d.js maps one to the other).

import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { frameClock, MIN_FRAME_MS } from "../panels/frame-clock.js";
import { BlinkController } from "./blink.js";
import { GazeController } from "./gaze.js";
import { expression } from "./moods.js";
import { VisemeTrack } from "./viseme-track.js";
import { VisemeMixer } from "./viseme-mix.js";
import { rig } from "./rig3d.js";
import { mouthShape } from "./visemes.js";

const MOOD_TAU_MS = 160;
/** Between blinks and speech the head only breathes and drifts: 30 fps where a GPU draws it. */
const CALM_FRAME_MS = 32;
/**
 * On software WebGL, where a frame costs the CPU ~20 ms, the calm head draws at 12 fps, as the 2D face does: the
 * page's other work (speech, the microphone, the camera) keeps its CPU time. Speech, blinks and gaze moves draw at
 * the frame clock's cap.
 */
const SOFTWARE_CALM_FRAME_MS = 83;
/** Eyes and head on their way to a new gaze target draw at the camera's 15 fps, as on the 2D face. */
const TURN_FRAME_MS = 66;
const TRACE_FRAMES = 900; // ~15 s at 60 fps, for the tests' timing checks
const FRAME_LOG = 1200; // frames whose cost the debug hook keeps, as avatar.js does
const MIN_PIXEL_RATIO = 0.45; // below this the head turns visibly blurry; slower machines get fewer frames
const VIEW_HEIGHT_M = 0.36; // what the stage shows of the avatar: hair to upper chest, like the 2D face
/** The generated models (scripts/avatar-gen): the lite one has a third of the triangles, for software WebGL. */
const MODEL_URL = "assets/avatar.glb";
const LITE_MODEL_URL = "assets/avatar-lite.glb";

export class Avatar3D {
  /**
   * Loads the model from `url` (by default the one for this WebGL: see below); rejects when WebGL or the model is
   * unavailable (the caller falls back to 2D).
   */
  static async create(canvas, audioClock, url = null, { syncFrames = false, quality = {} } = {}) {
    // Software WebGL (SwiftShader, llvmpipe: no GPU) does all the work on the CPU, about 0.5 us per triangle and
    // more per shaded pixel: there the head is the lite model, with Lambert materials and without multisampling,
    // and drops its resolution when frames come late (see `adapt`), so it stays smooth; a GPU gets the full
    // model, physically based materials and antialiasing.
    const software = quality.software ?? true;
    url ??= software ? LITE_MODEL_URL : MODEL_URL;
    const antialias = quality.antialias ?? !software;
    const material = quality.material ?? (software ? "lambert" : "standard");
    const renderer = new THREE.WebGLRenderer({ canvas, antialias, alpha: true, powerPreference: "low-power" });
    const gltf = await new GLTFLoader().loadAsync(url);
    gltf.scene.traverse((o) => {
      if (!o.isMesh) return;
      const m = o.material;
      if (material === "lambert" || material === "phong") {
        const opts = { name: m.name, color: m.color, vertexColors: m.vertexColors, side: m.side, emissive: m.emissive };
        if (material === "lambert") o.material = new THREE.MeshLambertMaterial(opts);
        else o.material = new THREE.MeshPhongMaterial({ ...opts, shininess: (1 - m.roughness) * 80, specular: 0x333333 });
      }
      if (SKIN_MATERIALS.has(m.name)) softSkin(o.material);
    });
    const avatar = new Avatar3D(canvas, audioClock, renderer, gltf, syncFrames, quality.view);
    avatar.quality = { software, model: url, antialias, material, pixelRatio: renderer.getPixelRatio(), adaptive: quality.adaptive ?? true };
    if (quality.pixelRatio) avatar.setPixelRatio(quality.pixelRatio);
    return avatar;
  }

  /**
   * `syncFrames` waits for the drawing at the end of each frame with a one-pixel read of the canvas, so that a
   * frame's measured cost includes the drawing itself and not only the commands' submission: for the benchmark,
   * which compares it with the 2D face, synchronised the same way. `gl.finish` is not enough: in Chromium it
   * returns before SwiftShader has drawn (a frame that takes 19 ms to read back "finishes" in 1 ms).
   */
  constructor(canvas, audioClock, renderer, gltf, syncFrames = false, view = {}) {
    this.syncFrames = syncFrames;
    this.syncPixel = new Uint8Array(4);
    this.frameMs = [];
    this.canvas = canvas;
    this.audioClock = audioClock;
    this.renderer = renderer;
    this.blinks = new BlinkController();
    this.gaze = new GazeController();
    this.track = new VisemeTrack();
    this.mixer = new VisemeMixer();
    this.moodName = "neutral";
    this.moodTarget = expression("neutral");
    this.mood = { ...this.moodTarget };
    this.viseme = "sil";
    this.weights = { sil: 1 };
    this.jaw = 0;
    this.eyelid = 1;
    this.last = performance.now();
    this.lastDraw = 0;
    this.frames = 0;
    this.trace = [];
    this.blinkLog = []; // [start, end] page times of recent blinks, for the interval tests
    this.schedule = []; // the viseme batches received, on the audio clock, for the timing tests
    this.wasBlinking = false;

    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    renderer.outputColorSpace = THREE.SRGBColorSpace;
    renderer.toneMapping = THREE.NeutralToneMapping;
    renderer.toneMappingExposure = 1.2;
    renderer.setClearColor(0x000000, 0); // the stage's own gradient shows through

    this.scene = new THREE.Scene();
    this.root = gltf.scene;
    this.scene.add(this.root);
    this.extras = gltf.parser.json.extras ?? {};
    const byName = (n) => {
      const o = this.root.getObjectByName(n);
      if (!o) throw new Error(`avatar model has no ${n}`);
      return o;
    };
    this.head = byName("Head");
    this.body = byName("Body");
    this.neck = byName("Neck");
    this.eyes = [byName("EyeLeft"), byName("EyeRight")];
    this.headRest = this.head.position.clone();
    /** Every mesh with morph targets, and its dictionary, so one weight name drives all meshes that have it. */
    this.morphMeshes = [];
    this.root.traverse((o) => {
      if (o.isMesh && o.morphTargetDictionary) this.morphMeshes.push(o);
      if (o.isMesh) o.frustumCulled = false; // morphs move vertices outside the rest bounds
    });
    // Draw the face first, then hair and body: their hidden parts (the hair's inside behind the head, the
    // shoulders behind the hair) then fail the depth test before they are shaded, which is most of the saving
    // on software WebGL, where every shaded pixel costs CPU time.
    for (const [name, order] of [["Hair", 1], ["Body", 2], ["Neck", 2]]) {
      this.root.getObjectByName(name)?.traverse((o) => {
        if (o.isMesh) o.renderOrder = order;
      });
    }
    this.mouthMesh = this.morphMeshes.find((o) => o.morphTargetDictionary.viseme_aa !== undefined);
    this.lidMesh = this.morphMeshes.find((o) => o.morphTargetDictionary.eyeBlinkLeft !== undefined);

    // Soft light: a warm sky and a cool floor, a key from the viewer's upper left (where the 2D face's highlights
    // are), a cool fill from the right, and a teal rim from behind that separates the hair from the dark stage.
    this.scene.add(new THREE.HemisphereLight(0xfbf4f0, 0xa08c98, 1.5));
    const key = new THREE.DirectionalLight(0xfff4ec, 1.9);
    key.position.set(-0.6, 0.9, 1.2);
    // A fill from below the camera's right keeps the jaw and the neck from going muddy.
    const fill = new THREE.DirectionalLight(0xffe6dc, 0.75);
    fill.position.set(0.8, -0.2, 1);
    const rim = new THREE.DirectionalLight(0x7fe6d8, 0.35);
    rim.position.set(0.4, 0.6, -1);
    this.scene.add(key, fill, rim);

    this.camera = new THREE.PerspectiveCamera(22, 1, 0.05, 5);
    const c = this.extras.eyeCentre ?? [0, 0.16, 0.08];
    this.lookY = c[1] - 0.012 + (view.y ?? 0); // centred just below the eyes, as the 2D face's 1000-unit box is
    this.size = { w: 0, h: 0 };
    const fit = () => {
      const w = canvas.clientWidth;
      const h = canvas.clientHeight;
      if (w === 0 || h === 0) return;
      this.size = { w, h };
      renderer.setSize(w, h, false);
      this.camera.aspect = w / h;
      // Fit VIEW_HEIGHT_M into the smaller of the two sides, as the 2D face fits its 1000 units.
      const half = ((this.camera.fov / 2) * Math.PI) / 180;
      const fitH = (view.height ?? VIEW_HEIGHT_M) / Math.min(1, w / h);
      const dist = fitH / 2 / Math.tan(half);
      // `view.yaw` orbits the camera around the head (radians, positive: from the avatar's left), for the
      // three-quarter screenshots; the page itself looks straight on.
      const yaw = view.yaw ?? 0;
      this.camera.position.set(dist * Math.sin(yaw), this.lookY + 0.012, dist * Math.cos(yaw));
      this.camera.lookAt(0, this.lookY, 0);
      this.camera.updateProjectionMatrix();
      this.wake?.(); // redraw at once
    };
    new ResizeObserver(fit).observe(canvas);
    fit();

    this.wake = frameClock().add((now) => this.frame(now));
  }

  calmFrameMs() {
    return this.quality?.software ? SOFTWARE_CALM_FRAME_MS : CALM_FRAME_MS;
  }

  setPixelRatio(ratio) {
    this.renderer.setPixelRatio(ratio);
    if (this.size.w > 0) this.renderer.setSize(this.size.w, this.size.h, false);
    this.quality.pixelRatio = ratio;
  }

  /**
   * Keeps the frame rate up by trading resolution: each second, if frames came much later than the loop asks
   * for them (busy: every animation frame; calm: every CALM_FRAME_MS), the head renders fewer pixels; when they
   * come on time for a while, it goes back up towards the screen's own resolution.
   */
  adapt(now, interval, busy) {
    if (!this.quality?.adaptive) return;
    const wanted = busy ? MIN_FRAME_MS : this.calmFrameMs();
    const late = Math.min(4, interval / wanted);
    this.lateness = this.lateness === undefined ? late : this.lateness * 0.9 + late * 0.1;
    if (now - (this.lastAdapt ?? 0) < 1000) return;
    this.lastAdapt = now;
    const max = Math.min(window.devicePixelRatio || 1, 2);
    const pr = this.quality.pixelRatio;
    if (this.lateness > 1.6 && pr > MIN_PIXEL_RATIO) this.setPixelRatio(Math.max(MIN_PIXEL_RATIO, pr * 0.8));
    else if (this.lateness < 1.15 && pr < max && now - (this.lastRaise ?? 0) > 4000) {
      this.lastRaise = now;
      this.setPixelRatio(Math.min(max, pr * 1.12));
    }
  }

  blink(phases, fromServer = true) {
    this.blinks.blink(performance.now(), phases, fromServer);
    this.wake();
  }

  lookAt(x, y) {
    this.gaze.look(performance.now(), x, y);
    this.wake();
  }

  setMood(name, intensity = 1) {
    this.moodName = name;
    this.moodTarget = expression(name, intensity);
    this.wake();
  }

  scheduleVisemes(utterance, startS, items) {
    this.track.add(utterance, startS, items);
    this.mixer.add(utterance, startS, items);
    this.wake();
    const cues = items.filter((i) => i && typeof i.v === "string" && Number.isFinite(i.t_ms));
    this.schedule.push({ utterance, startS, items: cues.map((i) => ({ t_ms: i.t_ms, v: i.v })) });
    if (this.schedule.length > 16) this.schedule.shift();
  }

  stopSpeech(utterance) {
    this.track.clear(utterance);
    this.mixer.clear(utterance);
    this.wake();
  }

  /** Draws one frame; returns when the next is wanted: at the cap while it blinks, speaks or turns, calm
   * otherwise, and in time for the next blink the page does by itself. */
  frame(now) {
    const wasBusy = this.blinks.current !== null || this.mixer.pending > 0 || this.gazeMoving;
    this.draw(now, wasBusy);
    if (this.blinks.current !== null || this.mixer.pending > 0) return now;
    if (this.gazeMoving) return now + TURN_FRAME_MS;
    const nextBlink = this.blinks.owner === "page" ? this.blinks.nextAuto : Infinity;
    return Math.min(now + this.calmFrameMs(), Math.max(now, nextBlink));
  }

  draw(now, busy) {
    const interval = now - this.last;
    const dt = Math.min(100, Math.max(0, interval));
    this.last = now;
    this.lastDraw = now;
    this.adapt(now, interval, busy);
    const t0 = performance.now();
    this.step(now, dt);
    if (this.size.w > 0) {
      this.renderer.render(this.scene, this.camera);
      if (this.syncFrames) {
        const gl = this.renderer.getContext();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, this.syncPixel);
      }
    }
    const ms = performance.now() - t0;
    this.drawMs = this.drawMs === undefined ? ms : this.drawMs * 0.95 + ms * 0.05;
    this.frameMs.push([Math.round(now), ms]);
    if (this.frameMs.length > FRAME_LOG) this.frameMs.shift();
    this.frames += 1;
  }

  step(now, dt) {
    const km = 1 - Math.exp(-dt / MOOD_TAU_MS);
    for (const k of Object.keys(this.mood)) this.mood[k] += (this.moodTarget[k] - this.mood[k]) * km;
    const g = this.gaze.update(now, dt);
    // Eyes or head still on their way to a gaze target: draw every frame until they settle.
    const was = this.g;
    this.gazeMoving = !!was && Math.abs(g.eyeX - was.eyeX) + Math.abs(g.eyeY - was.eyeY) + Math.abs(g.yaw - was.yaw) + Math.abs(g.pitch - was.pitch) > 0.002;
    this.g = g;
    const blink = this.blinks.update(now);
    if (this.blinks.current && !this.wasBlinking) {
      this.blinkLog.push([Math.round(this.blinks.current.start), null]);
      if (this.blinkLog.length > 64) this.blinkLog.shift();
    } else if (!this.blinks.current && this.wasBlinking && this.blinkLog.length) {
      this.blinkLog[this.blinkLog.length - 1][1] = Math.round(now);
    }
    this.wasBlinking = this.blinks.current !== null;
    // The same eyelid figure as the 2D face reports (the blink narrowed by squint and by looking down).
    const lidBase = Math.max(0.1, Math.min(1.08, 1 - this.mood.squint - Math.max(0, g.eyeY) * 0.15));
    this.eyelid = blink * lidBase;

    const audioNow = this.audioClock();
    this.viseme = this.track.at(audioNow);
    this.weights = this.mixer.weights(audioNow);
    const r = rig({ gaze: g, blink, mood: this.mood, visemes: this.weights, nowMs: now });
    this.jaw = r.jaw;
    this.rigState = r;

    for (const mesh of this.morphMeshes) {
      const dict = mesh.morphTargetDictionary;
      const inf = mesh.morphTargetInfluences;
      inf.fill(0);
      for (const [name, w] of Object.entries(r.morphs)) {
        const i = dict[name];
        if (i !== undefined) inf[i] = w;
      }
    }
    for (const eye of this.eyes) eye.rotation.set(r.eyes.pitch, r.eyes.yaw, 0, "YXZ");
    this.head.rotation.set(r.head.pitch, r.head.yaw, r.head.roll, "YXZ");
    this.head.position.set(this.headRest.x, this.headRest.y + r.breath * 0.0008, this.headRest.z);
    // Breathing: the chest rises and the shoulders lift a little; the neck follows.
    this.body.scale.set(1 + r.breath * 0.004, 1 + r.breath * 0.006, 1 + r.breath * 0.006);
    this.neck.position.y = r.breath * 0.0008;

    const mouth = this.mouthMesh;
    const lids = this.lidMesh;
    const trace = {
      t: Math.round(now * 10) / 10,
      a: audioNow,
      jaw: this.jaw,
      open: mouth ? this.morphOpen(mouth) : 0,
      v: this.viseme,
      blink: lids ? lids.morphTargetInfluences[lids.morphTargetDictionary.eyeBlinkLeft] : 0,
      eyeYaw: this.eyes[0].rotation.y,
      headYaw: this.head.rotation.y,
    };
    this.trace.push(trace);
    if (this.trace.length > TRACE_FRAMES) this.trace.shift();
  }

  /** The mouth opening the mesh really has: its viseme and jaw morph influences, weighted by each one's jaw. */
  morphOpen(mesh) {
    const dict = mesh.morphTargetDictionary;
    const inf = mesh.morphTargetInfluences;
    let open = (inf[dict.jawOpen] ?? 0) * 1;
    for (const [name, i] of Object.entries(dict)) {
      if (name.startsWith("viseme_")) open += inf[i] * mouthShape(name.slice(7)).jaw;
    }
    return Math.min(1, open);
  }

  /** A snapshot for `window.agentDebug`, with the same fields as the 2D face's and the 3D ones after them. */
  debugState() {
    const r = this.rigState;
    return {
      eyelid: this.eyelid,
      blinks: this.blinks.completed,
      blinkOwner: this.blinks.owner,
      gaze: { ...this.gaze.target },
      gazeCommands: this.gaze.commands,
      eyeOffset: { x: this.gaze.eye.x, y: this.gaze.eye.y },
      head: { yaw: this.g?.yaw ?? 0, pitch: (this.g?.pitch ?? 0) * 0.6 },
      mood: this.moodName,
      viseme: this.viseme,
      jaw: this.jaw,
      drawMs: this.drawMs ?? 0,
      renderer: "3d",
      frameMs: this.frameMs.slice(),
      frames: this.frames,
      eyeRotation: { yaw: this.eyes[0].rotation.y, pitch: this.eyes[0].rotation.x },
      headRotation: { yaw: this.head.rotation.y, pitch: this.head.rotation.x, roll: this.head.rotation.z },
      morphs: r ? { ...r.morphs } : {},
      trace: this.trace.slice(),
      blinkLog: this.blinkLog.map((b) => b.slice()),
      schedule: this.schedule.slice(),
      // Triangles drawn by the last frame: what software WebGL's per-frame cost mostly follows (bench_avatar).
      quality: { ...this.quality, triangles: this.renderer.info.render.triangles },
    };
  }
}

/** The materials lit as skin (see `softSkin`). */
const SKIN_MATERIALS = new Set(["skin", "lips", "lids"]);

/**
 * Skin is not plastic: light scatters under it and comes out past the shadow's edge, warm. An approximation of
 * that: besides the usual diffuse term, each light adds a "wrapped" one (n.l shifted by SKIN_WRAP) tinted towards
 * red, which softens the terminator and warms it, as on the 2D face's shading. Works on three.js's Lambert
 * (software WebGL) and physically based (GPU) materials alike; it costs a few instructions per pixel.
 */
function softSkin(material) {
  const chunk = material.isMeshStandardMaterial ? "lights_physical_pars_fragment" : "lights_lambert_pars_fragment";
  const plain = "vec3 irradiance = dotNL * directLight.color;";
  const source = THREE.ShaderChunk[chunk];
  if (!source.includes(plain)) return; // another three.js: keep its plain lighting
  const wrapped = `${plain}
	{
		float ndl = dot( geometryNormal, directLight.direction );
		float scatter = saturate( ( ndl + ${SKIN_WRAP.toFixed(2)} ) / ${(1 + SKIN_WRAP).toFixed(2)} ) - dotNL;
		reflectedLight.directDiffuse += scatter * vec3( 0.55, 0.32, 0.24 ) * directLight.color * BRDF_Lambert( material.diffuseColor );
	}`;
  // On a GPU, fine normal detail as well: a faint bump of value noise a few millimetres across, fixed to the
  // model (so it does not swim as the head moves), which breaks up the smooth plastic look of the shading. Software
  // WebGL leaves it out: it costs per pixel, and at the resolution it draws there it would not show.
  const detail = material.isMeshStandardMaterial;
  material.onBeforeCompile = (shader) => {
    shader.fragmentShader = shader.fragmentShader.replace(`#include <${chunk}>`, source.replace(plain, wrapped));
    if (!detail) return;
    shader.vertexShader = shader.vertexShader
      .replace("#include <common>", "#include <common>\nvarying vec3 vSkinPos;")
      .replace("#include <project_vertex>", "#include <project_vertex>\n\tvSkinPos = transformed;");
    shader.fragmentShader = shader.fragmentShader
      .replace("#include <common>", `#include <common>\n${SKIN_NOISE}`)
      .replace("#include <normal_fragment_maps>", `#include <normal_fragment_maps>
	{
		// Bump mapping from screen-space derivatives (as three.js's bump map does), with noise for the height.
		float h = skinNoise( vSkinPos * 380.0 ) * 0.00005 + skinNoise( vSkinPos * 1100.0 ) * 0.000015;
		vec3 sx = dFdx( - vViewPosition );
		vec3 sy = dFdy( - vViewPosition );
		vec3 r1 = cross( sy, normal );
		vec3 r2 = cross( normal, sx );
		float det = dot( sx, r1 );
		vec3 grad = sign( det ) * ( dFdx( h ) * r1 + dFdy( h ) * r2 );
		normal = normalize( abs( det ) * normal - grad );
	}`);
  };
  material.customProgramCacheKey = () => `soft-skin-${chunk}-${detail}`;
}

/** Smooth value noise in 3D (for the skin's normal detail). */
const SKIN_NOISE = `varying vec3 vSkinPos;
float skinHash( vec3 p ) { return fract( sin( dot( p, vec3( 127.1, 311.7, 74.7 ) ) ) * 43758.5453 ); }
float skinNoise( vec3 p ) {
	vec3 i = floor( p );
	vec3 f = fract( p );
	f = f * f * ( 3.0 - 2.0 * f );
	return mix(
		mix( mix( skinHash( i ), skinHash( i + vec3( 1, 0, 0 ) ), f.x ), mix( skinHash( i + vec3( 0, 1, 0 ) ), skinHash( i + vec3( 1, 1, 0 ) ), f.x ), f.y ),
		mix( mix( skinHash( i + vec3( 0, 0, 1 ) ), skinHash( i + vec3( 1, 0, 1 ) ), f.x ), mix( skinHash( i + vec3( 0, 1, 1 ) ), skinHash( i + vec3( 1, 1, 1 ) ), f.x ), f.y ),
		f.z );
}`;
const SKIN_WRAP = 0.55;

