// The 3D preview: a motion's glTF (GLB) played by an AnimationMixer on its ground and a grid.
// Imported dynamically by app.js, so the page still works when three.js is not installed.

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

/** The character's colour (one material for every segment, so it stands out from the ground). */
export const CHARACTER_COLOR = 0xe07b39;
/** The second character's colour (showCompanion: e.g. the motion simulated in MuJoCo). */
export const COMPANION_COLOR = 0x3b7dd8;
const BACKGROUND = 0xeef1f5;
/** The colour of the motion's own ground (its GLB's "ground" node), a little darker than the grid. */
const GROUND_COLOR = 0xb4bdc7;
/** Where the camera looks from, relative to the character: front right, a little above (glTF: Y up, Z forward). */
const VIEW_DIRECTION = new THREE.Vector3(-0.72, 0.22, 0.66).normalize();

const GROUND_SIZE = 60; // m
const GRID_CELL = 0.5; // m

/**
 * The ground grid as a repeated texture: long GridHelper lines that pass behind the camera
 * are dropped by some software rasterizers (SwiftShader, headless Chromium).
 */
function gridTexture(renderer) {
  const canvas = document.createElement('canvas');
  canvas.width = canvas.height = 128;
  const ctx = canvas.getContext('2d');
  ctx.fillStyle = '#dfe4ea';
  ctx.fillRect(0, 0, 128, 128);
  ctx.fillStyle = '#9eabb8';
  ctx.fillRect(0, 0, 128, 3);
  ctx.fillRect(0, 0, 3, 128);
  const texture = new THREE.CanvasTexture(canvas);
  texture.colorSpace = THREE.SRGBColorSpace;
  texture.wrapS = texture.wrapT = THREE.RepeatWrapping;
  texture.repeat.set(GROUND_SIZE / GRID_CELL, GROUND_SIZE / GRID_CELL);
  texture.anisotropy = renderer.capabilities.getMaxAnisotropy();
  return texture;
}

export class Viewer {
  constructor(canvas) {
    this.canvas = canvas;
    // preserveDrawingBuffer: the canvas can be read back (screenshots, tests)
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(BACKGROUND);
    this.scene.fog = new THREE.Fog(BACKGROUND, 6, 22);
    this.camera = new THREE.PerspectiveCamera(40, 16 / 10, 0.05, 200);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.enableDamping = true;

    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8d9299, 1.8));
    const sun = new THREE.DirectionalLight(0xffffff, 2.2);
    sun.position.set(-3, 6, 4);
    this.scene.add(sun);

    // the world: the motion's GLB carries its ground (a node "ground": a ramp, treads, a path) in a
    // world where gravity points down; a GLB without one is in the solver's frame and the world is
    // tilted so that the motion's gravity points down (a slope looks like one)
    this.world = new THREE.Group();
    this.scene.add(this.world);
    this.grid = new THREE.Mesh(
      new THREE.PlaneGeometry(GROUND_SIZE, GROUND_SIZE),
      new THREE.MeshStandardMaterial({ map: gridTexture(this.renderer), roughness: 1 }),
    );
    this.grid.rotation.x = -Math.PI / 2;
    this.world.add(this.grid);
    this.groundMaterial = new THREE.MeshStandardMaterial({ color: GROUND_COLOR, roughness: 0.95, side: THREE.DoubleSide });
    this.ground = null; // the motion's own ground, from its GLB
    this.groundNormal = new THREE.Vector3(0, 1, 0); // its normal (the world's up without one)

    this.material = new THREE.MeshStandardMaterial({ color: CHARACTER_COLOR, roughness: 0.6, metalness: 0 });
    this.companionMaterial = new THREE.MeshStandardMaterial({ color: COMPANION_COLOR, roughness: 0.6, metalness: 0 });
    this.companion = null; // {model, mixer, duration, start, time}: a second character beside the first
    this.cycleShift = new THREE.Vector3(); // how far the first character's clip moves in one loop
    this.model = null;
    this.mixer = null;
    this.pelvis = null;
    this.lastPelvis = new THREE.Vector3();
    this.playing = true;
    this.follow = true;
    this.frames = 0;
    this.waiting = [];
    this.timer = new THREE.Timer();

    this.resize();
    new ResizeObserver(() => this.resize()).observe(canvas.parentElement);
    this.renderer.setAnimationLoop(() => this.frame());
  }

  resize() {
    const box = this.canvas.parentElement;
    const w = box.clientWidth, h = box.clientHeight;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  /** Shows the motion in `glb` (an ArrayBuffer); `gravity` is the motion's gravity (motionx axes: Z up).
   * Returns the clip's duration and name, and how many three.js objects the model has. */
  async show(glb, { gravity, treads } = {}) {
    const gltf = await new GLTFLoader().parseAsync(glb, '');
    this.clear();
    this.model = gltf.scene;
    let objects = 0;
    this.model.traverse(() => { objects += 1; });
    const ground = this.model.getObjectByName('ground');
    if (ground) this.placeGround(ground); // a GLB in its world: drawn as it is, nothing tilted
    this.model.traverse((o) => {
      if (o.isMesh) {
        o.material = this.material;
        o.frustumCulled = false; // skinned: the bind-pose bounds do not follow the walk
      }
    });
    this.world.add(this.model);
    if (!ground) this.drawTreads(treads);
    this.mixer = new THREE.AnimationMixer(this.model);
    const clip = gltf.animations[0];
    if (clip) this.mixer.clipAction(clip).play();
    this.duration = clip ? clip.duration : 0;
    this.pelvis = this.model.getObjectByName('pelvis') || this.firstBone(this.model) || this.model;
    this.cycleShift = this.pelvisShift(this.mixer, this.pelvis, this.duration);
    this.mixer.setTime(0);
    this.frameCamera();
    this.tilt(ground ? undefined : gravity);

    this.world.updateMatrixWorld(true);
    this.pelvis.getWorldPosition(this.lastPelvis);
    this.world.localToWorld(this.controls.target);
    this.world.localToWorld(this.camera.position);
    this.controls.update();
    await this.nextFrame();
    return { duration: clip ? clip.duration : 0, name: clip ? clip.name : '', objects };
  }

  /**
   * The motion's own ground (its GLB's node "ground", at the scene's root): drawn in the ground's
   * colour beside the character, and the grid laid in its plane just under its lowest point (under
   * the lowest tread of stairs), so the grid neither cuts a ramp nor hides a stair going down.
   */
  placeGround(ground) {
    ground.removeFromParent(); // out of the character: the camera frames the character alone
    ground.traverse((o) => {
      if (o.isMesh) o.material = this.groundMaterial;
    });
    this.world.add(ground);
    this.ground = ground;
    const desc = (ground.userData && ground.userData.ground) || {};
    const n = Array.isArray(desc.normal) ? new THREE.Vector3(...desc.normal).normalize() : new THREE.Vector3(0, 1, 0);
    this.groundNormal.copy(n);
    let lowest = Infinity;
    const v = new THREE.Vector3();
    ground.traverse((o) => {
      const pos = o.isMesh ? o.geometry.attributes.position : null;
      for (let i = 0; pos && i < pos.count; i += 1) lowest = Math.min(lowest, v.fromBufferAttribute(pos, i).dot(n));
    });
    this.grid.quaternion.setFromUnitVectors(new THREE.Vector3(0, 0, 1), n); // the plane's normal is its +Z
    this.grid.position.copy(n).multiplyScalar((Number.isFinite(lowest) ? lowest : 0) - 0.005);
  }

  /** Points the camera at the character's first pose (in the untilted world's frame), and at the
   * second character's too when one walks beside it (showCompanion). */
  frameCamera() {
    const q = this.world.quaternion.clone();
    this.world.quaternion.identity();
    this.world.updateMatrixWorld(true);
    const box = new THREE.Box3().setFromObject(this.model, true); // skinned: the posed vertices
    if (this.companion) box.union(new THREE.Box3().setFromObject(this.companion.model, true));
    const center = box.getCenter(new THREE.Vector3());
    const size = Math.max(box.getSize(new THREE.Vector3()).length(), 0.5);
    const distance = (0.75 * size) / Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2));
    this.controls.target.copy(center);
    this.camera.position.copy(center).addScaledVector(VIEW_DIRECTION, distance);
    this.world.quaternion.copy(q);
    this.world.updateMatrixWorld(true);
  }

  /** The share (0-1) of `object`'s posed bounding box corners inside the camera's view. */
  inView(object) {
    this.scene.updateMatrixWorld(true);
    this.camera.updateMatrixWorld(true);
    const box = new THREE.Box3().setFromObject(object, true);
    if (box.isEmpty()) return 0;
    let inside = 0;
    for (let i = 0; i < 8; i += 1) {
      const p = new THREE.Vector3(i & 1 ? box.max.x : box.min.x, i & 2 ? box.max.y : box.min.y, i & 4 ? box.max.z : box.min.z);
      p.project(this.camera);
      if (Math.abs(p.x) <= 1 && Math.abs(p.y) <= 1 && p.z >= -1 && p.z <= 1) inside += 1;
    }
    return inside / 8;
  }

  /** Stairs: one box per stance, its top at the tread's height (motionx x, y, z → glTF z, x, y). */
  drawTreads(treads) {
    if (this.treads) {
      this.world.remove(this.treads);
      this.treads.traverse((o) => o.geometry && o.geometry.dispose());
      this.treads = null;
    }
    if (!Array.isArray(treads) || !treads.length) return;
    this.treads = new THREE.Group();
    this.treads.name = 'treads';
    const bottom = Math.min(0, ...treads.map((t) => t.center[2])) - 0.02;
    const material = new THREE.MeshStandardMaterial({ color: 0xb9bec6, roughness: 0.9 });
    for (const t of treads) {
      const [x, y, z] = t.center;
      const height = Math.max(z - bottom, 0.01);
      const box = new THREE.Mesh(new THREE.BoxGeometry(0.5, height, 0.32), material);
      box.position.set(y, bottom + height / 2, x);
      this.treads.add(box);
    }
    this.world.add(this.treads);
  }

  /** Where the pelvis is at the clip's end minus where it is at its start, along the ground (world's frame). */
  pelvisShift(mixer, pelvis, duration) {
    const at = (t) => {
      mixer.setTime(t);
      this.world.updateMatrixWorld(true);
      return this.world.worldToLocal(pelvis.getWorldPosition(new THREE.Vector3()));
    };
    const shift = at(duration).sub(at(0));
    return shift.addScaledVector(this.groundNormal, -shift.dot(this.groundNormal)); // up a ramp, not off it
  }

  /**
   * A second character beside the first (`glb`, e.g. the motion simulated in MuJoCo), `offset` m to
   * its left and in another colour. The two play together: the second's clip from its start, the
   * first's from its time `start` (s) on, looping cycle after cycle, each loop moved on by the
   * distance its clip walks, so both walk side by side; both start again when the second's clip ends.
   * Returns the second clip's duration and how many three.js objects it has.
   */
  async showCompanion(glb, { offset = 0.9, start = 0 } = {}) {
    const gltf = await new GLTFLoader().parseAsync(glb, '');
    this.clearCompanion();
    const model = gltf.scene;
    model.name = 'companion';
    const ownGround = model.getObjectByName('ground');
    if (ownGround) ownGround.removeFromParent(); // it walks beside the first character, on its ground
    model.traverse((o) => {
      if (o.isMesh) {
        o.material = this.companionMaterial;
        o.frustumCulled = false;
      }
    });
    model.position.x = offset; // glTF x = motionx y: to the character's left
    this.world.add(model);
    const mixer = new THREE.AnimationMixer(model);
    const clip = gltf.animations[0];
    if (clip) mixer.clipAction(clip).play();
    this.companion = { model, mixer, duration: clip ? clip.duration : 0, start: Math.max(0, start || 0), time: 0 };
    this.pairAt(0);
    // both in view: the camera framed again on the two, looking at them from as far as they need
    this.frameCamera();
    this.world.updateMatrixWorld(true);
    this.world.localToWorld(this.controls.target);
    this.world.localToWorld(this.camera.position);
    if (this.pelvis) this.pelvis.getWorldPosition(this.lastPelvis);
    this.controls.update();
    await this.nextFrame();
    let objects = 0;
    model.traverse(() => { objects += 1; });
    return { duration: this.companion.duration, objects };
  }

  /** Both characters at time `t` of the second's clip (showCompanion). */
  pairAt(t) {
    const c = this.companion;
    c.time = t;
    c.mixer.setTime(t);
    if (!this.model || !this.mixer) return;
    const d = this.duration;
    const tr = c.start + t;
    const loops = d > 0 ? Math.floor(tr / d) : 0;
    this.mixer.setTime(d > 0 ? tr - loops * d : 0);
    this.model.position.copy(this.cycleShift).multiplyScalar(loops);
  }

  clearCompanion() {
    const c = this.companion;
    this.companion = null;
    if (this.model) this.model.position.set(0, 0, 0);
    if (!c) return;
    c.mixer.stopAllAction();
    this.world.remove(c.model);
    c.model.traverse((o) => o.geometry && o.geometry.dispose());
  }

  clear() {
    this.clearCompanion();
    this.drawTreads(null);
    if (this.ground) {
      this.world.remove(this.ground);
      this.ground.traverse((o) => o.geometry && o.geometry.dispose());
      this.ground = null;
    }
    this.groundNormal.set(0, 1, 0);
    this.grid.quaternion.setFromAxisAngle(new THREE.Vector3(1, 0, 0), -Math.PI / 2);
    this.grid.position.set(0, 0, 0);
    if (!this.model) return;
    this.mixer.stopAllAction();
    this.world.remove(this.model);
    this.model.traverse((o) => o.geometry && o.geometry.dispose());
    this.model = this.mixer = this.pelvis = null;
  }

  firstBone(root) {
    let bone = null;
    root.traverse((o) => { if (!bone && o.isBone) bone = o; });
    return bone;
  }

  /** Rotates the world so that gravity (motionx axes x forward, y left, z up) points down. */
  tilt(gravity) {
    this.world.quaternion.identity();
    if (!Array.isArray(gravity) || gravity.length !== 3) return;
    const [gx, gy, gz] = gravity; // glTF axes: (x, y, z)_gltf = (y, z, x)_motionx
    const g = new THREE.Vector3(gy, gz, gx);
    if (g.lengthSq() === 0) return;
    this.world.quaternion.setFromUnitVectors(g.normalize(), new THREE.Vector3(0, -1, 0));
  }

  setPlaying(on) { this.playing = on; }

  setFollow(on) { this.follow = on; }

  setCharacterVisible(on) { if (this.model) this.model.visible = on; }

  /** Resolves once the next frame has been rendered. */
  nextFrame() { return new Promise((resolve) => this.waiting.push(resolve)); }

  frame() {
    this.timer.update();
    const dt = Math.min(this.timer.getDelta(), 0.1);
    if (this.companion && this.playing) {
      const c = this.companion;
      this.pairAt(c.duration > 0 ? (c.time + dt) % c.duration : 0);
    } else if (this.mixer && this.playing) {
      this.mixer.update(dt);
    }
    if (this.pelvis && this.follow) {
      // move the camera with the character (the clip loops: it jumps back with it)
      this.world.updateMatrixWorld(true);
      const now = this.pelvis.getWorldPosition(new THREE.Vector3());
      const delta = now.clone().sub(this.lastPelvis);
      this.camera.position.add(delta);
      this.controls.target.add(delta);
      this.lastPelvis.copy(now);
    }
    this.controls.update();
    this.renderer.render(this.scene, this.camera);
    this.frames += 1;
    const waiting = this.waiting;
    this.waiting = [];
    waiting.forEach((resolve) => resolve());
  }
}
