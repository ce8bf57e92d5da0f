#!/usr/bin/env node
// Independent USD reader for the tests: loads a USD layer with TinyUSDZ
// (npm package tinyusdz 0.9.0-rc10, vendored in ./tinyusdz/) and prints its
// Mesh prims as one JSON object on stdout. See README.md beside this file.
//
//   node tests/usd/read_usd.mjs FILE.usda [PRIM_PATH]
//
// Exit codes: 0 ok; 1 usage error, unreadable file or no such Mesh prim;
// 2 TinyUSDZ cannot parse the layer; 3 it parsed the layer but could not
// turn its meshes into render meshes (e.g. primvars:st without interpolation).
//
// Works with Node 18 (Debian 12) and Node 20: no Node-20-only API is used.

import { readFileSync } from 'node:fs';
import { webcrypto } from 'node:crypto';

const TINYUSDZ_VERSION = '0.9.0-rc10';
const USAGE = 'usage: node read_usd.mjs FILE.usda [PRIM_PATH]';

function fail(code, message) {
  process.stderr.write(`read_usd: ${message}\n`);
  process.exit(code);
}

const args = process.argv.slice(2);
if (args.includes('--time') || args.some((a) => a.startsWith('--time='))) {
  fail(1, '--time is not supported: the tinyusdz JS API has no way to choose a time code; ' +
    'it evaluates every attribute at the default time, which for an attribute that has ' +
    'only time samples is its earliest sample (the only one in a per-frame layer).');
}
if (args.length < 1 || args.length > 2 || args.some((a) => a.startsWith('-'))) {
  fail(1, USAGE);
}
const [file, primPath] = args;

let bytes;
try {
  bytes = new Uint8Array(readFileSync(file));
} catch (e) {
  fail(1, `cannot read ${file}: ${e.message}`);
}

// tinyusdz.mjs is an Emscripten build for the web only: it runs under Node once
// the script looks like a web page, with the .wasm bytes handed over directly.
globalThis.window = globalThis;
process.type = 'renderer';
if (!globalThis.crypto) globalThis.crypto = webcrypto; // Node 18 has no global crypto.

const here = new URL('./tinyusdz/', import.meta.url);
const { default: initTinyUSDZ } = await import(new URL('tinyusdz.mjs', here).href);
// Keep stdout for our JSON: what the library prints is held back, then shown on
// stderr if the run succeeds (a failure's message already holds usd.error()).
const libraryOutput = [];
const native = await initTinyUSDZ({
  wasmBinary: readFileSync(new URL('tinyusdz.wasm', here)),
  print: (s) => libraryOutput.push(s),
  printErr: (s) => libraryOutput.push(s),
});

const usd = new native.TinyUSDZLoaderNative();
if (!usd.loadAsLayerFromBinary(bytes, file)) {
  fail(2, `tinyusdz cannot parse ${file}:\n${usd.error()}`);
}
if (!usd.layerToRenderScene()) {
  fail(3, `tinyusdz parsed ${file} but could not convert its meshes:\n${usd.error()}`);
}

const list = (view) => (view === undefined ? null : Array.from(view));

const meshes = [];
for (let i = 0; i < usd.numMeshes(); i++) {
  const m = usd.getMesh(i);
  if (primPath !== undefined && m.absPath !== primPath) continue;
  const st = list(m.texcoords);
  meshes.push({
    path: m.absPath,
    points: list(m.points),
    faceVertexCounts: list(m.faceVertexCounts),
    faceVertexIndices: list(m.faceVertexIndices),
    st,
    st_indices: null,
    st_interpolation: st === null ? null : 'vertex',
    velocities: null,
    normals: list(m.normals),
    extent: null,
    unavailable: ['velocities', 'extent', 'st_indices'],
  });
}

if (primPath !== undefined && meshes.length === 0) {
  fail(1, `no Mesh prim at ${primPath} in ${file}`);
}

for (const s of libraryOutput) if (s.trim() !== '') process.stderr.write(`tinyusdz: ${s}\n`);
process.stdout.write(JSON.stringify({
  reader: { package: 'tinyusdz', version: TINYUSDZ_VERSION, form: 'render-mesh' },
  meshes,
}) + '\n');
