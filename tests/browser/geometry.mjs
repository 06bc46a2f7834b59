// SPDX-License-Identifier: MIT
// The dashboard's pure helpers (web/dashboard/src/geometry.ts, compiled by run.sh) against
// hand-made cases: the running box of a long walk is the box of its every row (non-finite rows
// skipped); the 95 % ellipse of a covariance; the trail row in force at a time; a long trail
// thinned to its limit with its recent rows whole.
// usage: node geometry.mjs DIR_WITH_geometry.js
import { pathToFileURL } from 'node:url';
import path from 'node:path';

const dir = process.argv[2];
const { Bounds, ellipse95, rowAt, thinTrail } = await import(pathToFileURL(path.join(dir, 'geometry.js')).href);
const fail = (msg) => { console.error('FAIL: ' + msg); process.exit(1); };
const near = (a, b, what) => { if (!(Math.abs(a - b) < 1e-9)) fail(`${what}: ${a} != ${b}`); };

// A long walk 1 km from the origin, with a non-finite row the box must skip.
const bounds = new Bounds();
let minx = Infinity, maxx = -Infinity, miny = Infinity, maxy = -Infinity;
for (let i = 0; i < 20000; i++) {
  const x = 1000 + 30 * Math.cos(i / 500), y = -400 + 12 * Math.sin(i / 300);
  bounds.add(x, y);
  minx = Math.min(minx, x), maxx = Math.max(maxx, x), miny = Math.min(miny, y), maxy = Math.max(maxy, y);
}
bounds.add(NaN, Infinity);
const bx = [], by = [];
bounds.corners(bx, by);
near(bx[0], minx, 'box min x'), near(bx[1], maxx, 'box max x'), near(by[0], miny, 'box min y'), near(by[1], maxy, 'box max y');
const empty = [], emptyY = [];
new Bounds().corners(empty, emptyY);
if (empty.length || emptyY.length) fail('an empty box gives corners');

// The 95 % ellipse (chi-square 2 dof, 5.991): sxx 4, syy 1 -> semi-axes 2 sqrt(5.991) along x
// and sqrt(5.991); the same covariance rotated by 30 degrees turns the ellipse by 30 degrees.
const e = ellipse95(4, 0, 1);
near(e.a, 2 * Math.sqrt(5.991), 'a'), near(e.b, Math.sqrt(5.991), 'b'), near(e.angle, 0, 'angle');
const c = Math.cos(Math.PI / 6), s = Math.sin(Math.PI / 6);
const r = ellipse95(4 * c * c + s * s, 3 * c * s, 4 * s * s + c * c);
near(r.a, e.a, 'rotated a'), near(r.b, e.b, 'rotated b'), near(r.angle, Math.PI / 6, 'rotated angle');

// The row in force at t: the last at or before it; none before the first.
const trail = [[0, 0], [1, 1], [2, 2], [5, 5]];
if (rowAt(trail, -1) !== null) fail('a row before the trail starts');
if (rowAt(trail, 1)[0] !== 1 || rowAt(trail, 4.9)[0] !== 2 || rowAt(trail, 99)[0] !== 5) fail('rowAt');
// A long trail thinned: within the limit, the recent rows whole, the older every other one.
const long = Array.from({ length: 5001 }, (_, i) => [i, i, 0]);
if (thinTrail(long.slice(0, 4000), 4000, 1200) !== null) fail('a trail within the limit was thinned');
const thin = thinTrail(long, 4000, 1200);
if (thin.length !== 1901 + 1200) fail(`thinned to ${thin.length} rows`);
if (thin[0][0] !== 0 || thin[1][0] !== 2 || thin[thin.length - 1][0] !== 5000) fail('thinning kept the wrong rows');
for (let i = thin.length - 1199; i < thin.length; i++) if (thin[i][0] - thin[i - 1][0] !== 1) fail('the recent rows are not whole');
console.log('geometry: running box = box of every row; 95 % ellipse as computed by hand; rowAt');
