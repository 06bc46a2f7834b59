// SPDX-License-Identifier: MIT
// The dashboard's pure helpers (web/dashboard/src/geometry.ts, compiled by run.sh) against
// hand-made cases: the view fitted from the trails' running bounds is the view fitted from
// every row; decimation keeps the first and last points and drops only those closer than its
// pixel limit to the last kept one.
// usage: node geometry.mjs DIR_WITH_geometry.js
import { pathToFileURL } from 'node:url';
import path from 'node:path';

const dir = process.argv[2];
const { Bounds, decimate, fitView } = await import(pathToFileURL(path.join(dir, 'geometry.js')).href);
const fail = (msg) => { console.error('FAIL: ' + msg); process.exit(1); };

// A long walk 1 km from the origin, with a non-finite row the bounds must skip.
const xs = [], ys = [];
const bounds = new Bounds();
for (let i = 0; i < 20000; i++) {
  const x = 1000 + 30 * Math.cos(i / 500), y = -400 + 12 * Math.sin(i / 300);
  xs.push(x), ys.push(y), bounds.add(x, y);
}
xs.push(NaN), ys.push(Infinity), bounds.add(NaN, Infinity);
const bx = [], by = [];
bounds.corners(bx, by);
const all = fitView(xs, ys, 1280, 800), fromBounds = fitView(bx, by, 1280, 800);
for (const k of ['scale', 'ox', 'oy']) {
  if (Math.abs(all[k] - fromBounds[k]) > 1e-9) fail(`fitView from the bounds: ${k} ${fromBounds[k]} != ${all[k]}`);
}
const empty = [], emptyY = [];
new Bounds().corners(empty, emptyY);
if (empty.length || emptyY.length) fail('an empty box gives corners');

// Decimation: points 0.5 px apart at 1.5 px keep every third, and the last one (5) always.
const line = Array.from({ length: 11 }, (_, i) => [0.5 * i, 0]);
const kept = decimate(line, 1.5).map((p) => p[0]);
if (kept.join(',') !== '0,1.5,3,4.5,5') fail(`decimate kept ${kept}`);
const spaced = Array.from({ length: 5 }, (_, i) => [3 * i, 1]);
if (decimate(spaced, 1.5).length !== 5) fail('decimate dropped points 3 px apart');
if (decimate([], 1.5).length !== 0 || decimate([[1, 2]], 1.5).length !== 1) fail('decimate of 0 or 1 points');
console.log('geometry: fitView from running bounds = from every row; decimation as stated');
