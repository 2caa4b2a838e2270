// Vertex positions (world frame) and displayed vertex colours of a GLB as three.js loads them
// (GLTFLoader with the meshopt decoder; three.js takes COLOR_0 as linear sRGB and the renderer
// writes sRGB, so the displayed colour is the sRGB encoding of the stored one). Prints one line
// "x y z r g b" per vertex. Used by colour_transfer.py.
//
// Usage: node glb_colours_three.mjs THREE_DIR FILE.glb   (THREE_DIR: node_modules/three of an
// `npm install three@0.170.0`)
import { readFileSync } from "node:fs";
import path from "node:path";

const base = path.resolve(process.argv[2]);
const THREE = await import(path.join(base, "build", "three.module.js"));
const { GLTFLoader } = await import(path.join(base, "examples/jsm/loaders/GLTFLoader.js"));
const { MeshoptDecoder } = await import(path.join(base, "examples/jsm/libs/meshopt_decoder.module.js"));

const bytes = readFileSync(process.argv[3]);
const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
const loader = new GLTFLoader();
loader.setMeshoptDecoder(MeshoptDecoder);
const gltf = await new Promise((ok, fail) => loader.parse(buffer, "", ok, fail));
gltf.scene.updateMatrixWorld(true);
const out = [];
const color = new THREE.Color();
gltf.scene.traverse((obj) => {
  if (!obj.isMesh) return;
  const pos = obj.geometry.attributes.position;
  const col = obj.geometry.attributes.color;
  if (!col) throw new Error("no COLOR_0");
  const v = new THREE.Vector3();
  for (let i = 0; i < pos.count; i++) {
    v.fromBufferAttribute(pos, i).applyMatrix4(obj.matrixWorld);
    // getX/Y/Z denormalize a normalized attribute; convertLinearToSRGB is the renderer's output
    // transfer (IEC 61966-2-1).
    color.setRGB(col.getX(i), col.getY(i), col.getZ(i)).convertLinearToSRGB();
    out.push(`${v.x} ${v.y} ${v.z} ${color.r} ${color.g} ${color.b}`);
  }
});
process.stdout.write(out.join("\n") + "\n");
