// Load a GLB with three.js's own GLTFLoader in Node (no browser) and print what three.js sees.
//
//   node tests/js/load_glb.mjs FILE.glb [TIME ...]
//
// TIME: seconds, or "end" (the clip's duration). Environment: THREE_DIR, the `three` package
// directory (default: service/web/node_modules/three beside this repository's tests/);
// ANIMATIONS=all: also evaluate every animation at each TIME (animation_poses).
//
// Prints one JSON object: counts (nodes, bones, skins, skinned meshes, meshes), every
// animation's duration and tracks (name, type, key count, interpolation), the world position
// and quaternion of every bone at rest and, for each TIME, after an AnimationMixer has
// evaluated the first animation at that time; plus the skinned world position of vertex 0
// of every skinned mesh and the height (Y) of its lowest skinned vertex (three.js's own
// skinning: SkinnedMesh.getVertexPosition).
//
// Shims: none by default. GLTFLoader.parse() on an ArrayBuffer needs only TextDecoder, which Node
// has; it touches the DOM (document, createImageBitmap, URL from `self`) only to decode images.
// IMAGES=stub (for a textured character): `self` is Node's global (URL.createObjectURL and Blob
// are Node's) and three.js's TextureLoader hands back a 1x1 placeholder image instead of decoding
// one, so the image's buffer view, the texture, its sampler and the material's map still go
// through GLTFLoader; `materials` lists each mesh material and whether it has a colour map.
// Errors (and GLTFLoader's onError) exit with status 1.

import { readFileSync } from 'node:fs';
import { dirname, resolve } from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const threeDir = process.env.THREE_DIR || resolve(here, '../../service/web/node_modules/three');
// the same file GLTFLoader's `import ... from 'three'` resolves to (package exports "."),
// so both share one module instance
const THREE = await import(pathToFileURL(resolve(threeDir, 'build/three.module.js')).href);
const { GLTFLoader } = await import(pathToFileURL(resolve(threeDir, 'examples/jsm/loaders/GLTFLoader.js')).href);

if (process.env.IMAGES === 'stub') {
  globalThis.self = globalThis;
  THREE.TextureLoader.prototype.load = function (url, onLoad) {
    const texture = new THREE.Texture();
    texture.image = { width: 1, height: 1, placeholder: url };
    setTimeout(() => onLoad && onLoad(texture), 0);
    return texture;
  };
}

const [file, ...timeArgs] = process.argv.slice(2);
if (!file) {
  console.error('usage: node load_glb.mjs FILE.glb [TIME ...]');
  process.exit(2);
}
const bytes = readFileSync(file);
const data = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);

const gltf = await new Promise((ok, fail) => new GLTFLoader().parse(data, '', ok, fail)).catch((e) => {
  console.error(`GLTFLoader failed: ${e && e.stack ? e.stack : e}`);
  process.exit(1);
});

const scene = gltf.scene;
const bones = [];
const skinned = [];
let meshes = 0;
scene.traverse((o) => {
  if (o.isBone) bones.push(o);
  if (o.isMesh) meshes += 1;
  if (o.isSkinnedMesh) skinned.push(o);
});
const skeletons = new Set(skinned.map((m) => m.skeleton));
const materials = [];
scene.traverse((o) => {
  if (o.isMesh) {
    for (const m of Array.isArray(o.material) ? o.material : [o.material]) {
      materials.push({ mesh: o.name, name: m.name, map: Boolean(m.map), color: m.color ? m.color.toArray() : null });
    }
  }
});

const vec = (v) => [v.x, v.y, v.z];
const quat = (q) => [q.x, q.y, q.z, q.w];

function pose() {
  scene.updateMatrixWorld(true);
  const world = {};
  for (const b of bones) {
    world[b.name] = {
      position: vec(b.getWorldPosition(new THREE.Vector3())),
      quaternion: quat(b.getWorldQuaternion(new THREE.Quaternion())),
    };
  }
  const vertex0 = {};
  const lowest = {};
  for (const m of skinned) {
    const v = m.getVertexPosition(0, new THREE.Vector3()); // skinned, in the mesh's space
    vertex0[m.name] = vec(v.applyMatrix4(m.matrixWorld));
    let low = Infinity;
    const n = m.geometry.attributes.position.count;
    for (let i = 0; i < n; i += 1) {
      low = Math.min(low, m.getVertexPosition(i, new THREE.Vector3()).applyMatrix4(m.matrixWorld).y);
    }
    lowest[m.name] = low;
  }
  return { bones: world, vertex0, lowest };
}

const rest = pose();
const animations = gltf.animations.map((clip) => ({
  name: clip.name,
  duration: clip.duration,
  tracks: clip.tracks.map((t) => ({
    name: t.name,
    type: t.ValueTypeName,
    keys: t.times.length,
    first: t.times[0],
    last: t.times[t.times.length - 1],
    interpolation: t.getInterpolation() === THREE.InterpolateLinear ? 'LINEAR'
      : t.getInterpolation() === THREE.InterpolateDiscrete ? 'STEP' : 'OTHER',
  })),
}));

function posesOf(clip) {
  const out = [];
  const mixer = new THREE.AnimationMixer(scene);
  const action = mixer.clipAction(clip);
  action.setLoop(THREE.LoopOnce, 1); // so that t = duration is the last key, not frame 0 again
  action.clampWhenFinished = true;
  for (const arg of timeArgs) {
    const t = arg === 'end' ? clip.duration : Number(arg);
    if (!Number.isFinite(t)) {
      console.error(`bad time ${arg}`);
      process.exit(2);
    }
    action.reset();
    action.play();
    mixer.setTime(t);
    out.push({ time: t, ...pose() });
  }
  action.stop();
  mixer.uncacheRoot(scene);
  return out;
}

const poses = gltf.animations.length > 0 && timeArgs.length > 0 ? posesOf(gltf.animations[0]) : [];
// ANIMATIONS=all: the same poses for every animation (a library GLB), with its extras
const animationPoses = process.env.ANIMATIONS === 'all' && timeArgs.length > 0
  ? gltf.animations.map((clip) => ({ name: clip.name, poses: posesOf(clip) })) : undefined;
const animationExtras = (gltf.parser.json.animations || []).map((a) => a.extras || null);

process.stdout.write(JSON.stringify({
  three_revision: THREE.REVISION,
  same_three_instance: scene instanceof THREE.Object3D,
  nodes: (gltf.parser.json.nodes || []).length,
  bones: bones.length,
  bone_names: bones.map((b) => b.name),
  skins: (gltf.parser.json.skins || []).length,
  skeletons: skeletons.size,
  skinned_meshes: skinned.length,
  meshes,
  materials,
  asset: gltf.asset,
  animations,
  animation_extras: animationExtras,
  rest,
  poses,
  animation_poses: animationPoses,
}) + '\n');
