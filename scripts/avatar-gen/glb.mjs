//! A minimal glTF 2.0 binary (GLB) writer: nodes, meshes with morph targets, vertex colours and PBR materials.
// @ts-check
//
// Written by hand instead of using three.js's GLTFExporter, which needs a DOM (FileReader, Blob) and does not
// promise byte-stable output. Everything here is deterministic: the same input gives the same bytes, which is what
// lets the repository commit the GLB and check that regenerating it changes nothing.

/**
 * @typedef {{ name: string, position: Float32Array, normal?: Float32Array }} Target
 * @typedef {{ position: Float32Array, normal: Float32Array, color?: Float32Array, indices: Uint32Array,
 *             material: number, targets: Target[] }} Primitive
 * @typedef {{ name: string, primitives: Primitive[], targetNames: string[], weights?: number[] }} Mesh
 * @typedef {{ name: string, baseColor: number[], roughness: number, metallic?: number, emissive?: number[],
 *             doubleSided?: boolean }} Material
 * @typedef {{ name: string, mesh?: number, children?: number[], translation?: number[], rotation?: number[],
 *             scale?: number[], extras?: object }} Node
 * @typedef {{ nodes: Node[], meshes: Mesh[], materials: Material[], scene: number[], generator: string,
 *             extras?: object }} Document
 */

const ARRAY_BUFFER = 34962;
const ELEMENT_ARRAY_BUFFER = 34963;
const FLOAT = 5126;
const UNSIGNED_SHORT = 5123;
const UNSIGNED_INT = 5125;

/** Rounds to float32 the way the accessor will store it, so min/max match the data exactly. */
function f32(v) {
  return Math.fround(v);
}

/** The GLB bytes of `doc`. */
export function writeGlb(doc) {
  /** @type {Uint8Array[]} */
  const chunks = [];
  let byteLength = 0;
  /** @type {object[]} */
  const bufferViews = [];
  /** @type {object[]} */
  const accessors = [];

  /** Appends `bytes` as a 4-byte aligned buffer view; returns its index. */
  const view = (bytes, target) => {
    const pad = (4 - (byteLength % 4)) % 4;
    if (pad) {
      chunks.push(new Uint8Array(pad));
      byteLength += pad;
    }
    const bv = { buffer: 0, byteOffset: byteLength, byteLength: bytes.byteLength };
    if (target) bv.target = target;
    bufferViews.push(bv);
    chunks.push(new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength));
    byteLength += bytes.byteLength;
    return bufferViews.length - 1;
  };

  /**
   * A VEC3/VEC4 float accessor over `data`; `bounds` adds min/max (required for positions). `sparse` stores only
   * the elements that are not all zero, as a glTF sparse accessor: a morph target moves a small part of a mesh
   * (the mouth's fields leave the forehead alone), and dense targets would make the file ten times larger.
   */
  const floatAccessor = (data, width, bounds, sparse = false) => {
    const arr = Float32Array.from(data);
    const count = arr.length / width;
    /** @type {any} */
    const acc = { componentType: FLOAT, count, type: width === 3 ? "VEC3" : "VEC4" };
    const moved = [];
    if (sparse) {
      for (let i = 0; i < count; i++) {
        for (let k = 0; k < width; k++) {
          if (arr[i * width + k] !== 0) {
            moved.push(i);
            break;
          }
        }
      }
    }
    if (sparse && moved.length * 2 < count) {
      const values = new Float32Array(moved.length * width);
      moved.forEach((i, j) => values.set(arr.subarray(i * width, i * width + width), j * width));
      const small = count <= 65535;
      acc.sparse = {
        count: moved.length,
        indices: small
          ? { bufferView: view(Uint16Array.from(moved)), componentType: UNSIGNED_SHORT }
          : { bufferView: view(Uint32Array.from(moved)), componentType: UNSIGNED_INT },
        values: { bufferView: view(values) },
      };
      if (moved.length === 0) {
        // A sparse accessor needs at least one entry: store element 0's (zero) value.
        acc.sparse = {
          count: 1,
          indices: { bufferView: view(Uint32Array.from([0])), componentType: UNSIGNED_INT },
          values: { bufferView: view(new Float32Array(width)) },
        };
      }
    } else {
      acc.bufferView = view(arr, ARRAY_BUFFER);
    }
    if (bounds) {
      const min = new Array(width).fill(Infinity);
      const max = new Array(width).fill(-Infinity);
      for (let i = 0; i < arr.length; i++) {
        const k = i % width;
        if (arr[i] < min[k]) min[k] = arr[i];
        if (arr[i] > max[k]) max[k] = arr[i];
      }
      acc.min = min.map(f32);
      acc.max = max.map(f32);
    }
    accessors.push(acc);
    return accessors.length - 1;
  };

  const indexAccessor = (indices, vertexCount) => {
    const small = vertexCount <= 65535;
    const arr = small ? Uint16Array.from(indices) : Uint32Array.from(indices);
    accessors.push({
      bufferView: view(arr, ELEMENT_ARRAY_BUFFER),
      componentType: small ? UNSIGNED_SHORT : UNSIGNED_INT,
      count: arr.length,
      type: "SCALAR",
    });
    return accessors.length - 1;
  };

  const meshes = doc.meshes.map((m) => {
    const primitives = m.primitives.map((p) => {
      const count = p.position.length / 3;
      const attributes = {
        POSITION: floatAccessor(p.position, 3, true),
        NORMAL: floatAccessor(p.normal, 3, false),
      };
      if (p.color) attributes.COLOR_0 = floatAccessor(p.color, 3, false);
      const prim = { attributes, indices: indexAccessor(p.indices, count), material: p.material, mode: 4 };
      if (p.targets.length) {
        prim.targets = p.targets.map((t) => {
          const out = { POSITION: floatAccessor(t.position, 3, true, true) };
          if (t.normal) out.NORMAL = floatAccessor(t.normal, 3, false, true);
          return out;
        });
      }
      return prim;
    });
    const mesh = { name: m.name, primitives };
    if (m.targetNames.length) {
      mesh.weights = m.weights ?? m.targetNames.map(() => 0);
      mesh.extras = { targetNames: m.targetNames };
    }
    return mesh;
  });

  const materials = doc.materials.map((m) => {
    const out = {
      name: m.name,
      pbrMetallicRoughness: {
        baseColorFactor: [...m.baseColor.map(f32), 1],
        metallicFactor: m.metallic ?? 0,
        roughnessFactor: f32(m.roughness),
      },
    };
    if (m.emissive) out.emissiveFactor = m.emissive.map(f32);
    if (m.doubleSided) out.doubleSided = true;
    return out;
  });

  const nodes = doc.nodes.map((n) => {
    const out = { name: n.name };
    if (n.mesh !== undefined) out.mesh = n.mesh;
    if (n.children?.length) out.children = n.children;
    if (n.translation) out.translation = n.translation.map(f32);
    if (n.rotation) out.rotation = n.rotation.map(f32);
    if (n.scale) out.scale = n.scale.map(f32);
    if (n.extras) out.extras = n.extras;
    return out;
  });

  const json = {
    asset: { version: "2.0", generator: doc.generator },
    scene: 0,
    scenes: [{ name: "avatar", nodes: doc.scene }],
    nodes,
    meshes,
    materials,
    accessors,
    bufferViews,
    buffers: [{ byteLength: 0 }],
  };
  if (doc.extras) json.extras = doc.extras;
  const binPad = (4 - (byteLength % 4)) % 4;
  json.buffers[0].byteLength = byteLength + binPad;

  const jsonBytes = new TextEncoder().encode(JSON.stringify(json));
  const jsonPad = (4 - (jsonBytes.length % 4)) % 4;
  const jsonLen = jsonBytes.length + jsonPad;
  const binLen = byteLength + binPad;
  const total = 12 + 8 + jsonLen + 8 + binLen;
  const out = new Uint8Array(total);
  const dv = new DataView(out.buffer);
  dv.setUint32(0, 0x46546c67, true); // "glTF"
  dv.setUint32(4, 2, true);
  dv.setUint32(8, total, true);
  dv.setUint32(12, jsonLen, true);
  dv.setUint32(16, 0x4e4f534a, true); // "JSON"
  out.set(jsonBytes, 20);
  out.fill(0x20, 20 + jsonBytes.length, 20 + jsonLen); // JSON pads with spaces
  let o = 20 + jsonLen;
  dv.setUint32(o, binLen, true);
  dv.setUint32(o + 4, 0x004e4942, true); // "BIN\0"
  o += 8;
  for (const c of chunks) {
    out.set(c, o);
    o += c.byteLength;
  }
  return out;
}

/** Parses a GLB into {json, bin} (for tests and for checking what a generator wrote). */
export function readGlb(bytes) {
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (dv.getUint32(0, true) !== 0x46546c67) throw new Error("not a GLB (bad magic)");
  if (dv.getUint32(4, true) !== 2) throw new Error("not glTF 2.0");
  if (dv.getUint32(8, true) !== bytes.byteLength) throw new Error("GLB length does not match the file");
  const jsonLen = dv.getUint32(12, true);
  if (dv.getUint32(16, true) !== 0x4e4f534a) throw new Error("first chunk is not JSON");
  const json = JSON.parse(new TextDecoder().decode(bytes.subarray(20, 20 + jsonLen)));
  const o = 20 + jsonLen;
  const binLen = dv.getUint32(o, true);
  if (dv.getUint32(o + 4, true) !== 0x004e4942) throw new Error("second chunk is not BIN");
  const bin = bytes.subarray(o + 8, o + 8 + binLen);
  return { json, bin };
}

/** The float data of accessor `index` of a parsed GLB (dense or sparse). */
export function accessorFloats(glb, index) {
  const acc = glb.json.accessors[index];
  const width = acc.type === "VEC3" ? 3 : acc.type === "VEC4" ? 4 : 1;
  const slice = (bufferView, bytes) => {
    const bv = glb.json.bufferViews[bufferView];
    const start = glb.bin.byteOffset + bv.byteOffset;
    return glb.bin.buffer.slice(start, start + bytes);
  };
  const out = acc.bufferView === undefined
    ? new Float32Array(acc.count * width)
    : new Float32Array(slice(acc.bufferView, acc.count * width * 4));
  if (acc.sparse) {
    const n = acc.sparse.count;
    const wide = acc.sparse.indices.componentType === UNSIGNED_INT;
    const idx = wide
      ? new Uint32Array(slice(acc.sparse.indices.bufferView, n * 4))
      : new Uint16Array(slice(acc.sparse.indices.bufferView, n * 2));
    const values = new Float32Array(slice(acc.sparse.values.bufferView, n * width * 4));
    idx.forEach((i, j) => out.set(values.subarray(j * width, j * width + width), i * width));
  }
  return out;
}
