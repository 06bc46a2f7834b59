// SPDX-License-Identifier: MIT
// Pure helpers (no DOM): the 95 % ellipse of a 2-D covariance, the view transform, lookups in a
// trail by time.
import type { TrailRow } from './api';

/** Semi-axes (m) and orientation (rad) of the 95 % confidence ellipse (chi-square 2 dof). */
export function ellipse95(sxx: number, sxy: number, syy: number): { a: number; b: number; angle: number } {
  const mean = (sxx + syy) / 2;
  const d = Math.sqrt(Math.max(0, ((sxx - syy) * (sxx - syy)) / 4 + sxy * sxy));
  const k = 5.991;
  return {
    a: Math.sqrt(k * Math.max(0, mean + d)),
    b: Math.sqrt(k * Math.max(0, mean - d)),
    angle: 0.5 * Math.atan2(2 * sxy, sxx - syy),
  };
}

/** Metres to pixels: y up in the world, down on the screen. */
export interface View {
  scale: number;
  ox: number;
  oy: number;
}

/** The view that shows every point with a 2 m margin. The frame's origin is not assumed to be
 *  near the building (spec 1.1: any origin), and the bounds are found in one pass: spreading
 *  an hour of trails into Math.min(...) exceeds the engine's argument limit. */
export function fitView(xs: number[], ys: number[], width: number, height: number): View {
  let minx = Infinity;
  let maxx = -Infinity;
  let miny = Infinity;
  let maxy = -Infinity;
  for (const x of xs) if (Number.isFinite(x)) (minx = Math.min(minx, x)), (maxx = Math.max(maxx, x));
  for (const y of ys) if (Number.isFinite(y)) (miny = Math.min(miny, y)), (maxy = Math.max(maxy, y));
  if (!(minx <= maxx)) (minx = 0), (maxx = 0);
  if (!(miny <= maxy)) (miny = 0), (maxy = 0);
  minx -= 2;
  maxx += 2;
  miny -= 2;
  maxy += 2;
  const scale = Math.max(1e-3, Math.min(width / (maxx - minx), height / (maxy - miny)));
  return { scale, ox: -minx * scale, oy: height + miny * scale };
}

export const toScreen = (v: View, x: number, y: number): [number, number] => [v.ox + x * v.scale, v.oy - y * v.scale];

/** A box that only grows: the trails' extent kept as rows arrive, so that fitting the view
 *  costs the same after four hours as after a minute. */
export class Bounds {
  minx = Infinity;
  maxx = -Infinity;
  miny = Infinity;
  maxy = -Infinity;
  add(x: number, y: number): void {
    if (Number.isFinite(x)) (this.minx = Math.min(this.minx, x)), (this.maxx = Math.max(this.maxx, x));
    if (Number.isFinite(y)) (this.miny = Math.min(this.miny, y)), (this.maxy = Math.max(this.maxy, y));
  }
  /** Its corners, for fitView (nothing when empty). */
  corners(xs: number[], ys: number[]): void {
    if (this.minx <= this.maxx) xs.push(this.minx, this.maxx);
    if (this.miny <= this.maxy) ys.push(this.miny, this.maxy);
  }
}

/** The points of a polyline worth drawing at this scale: each at least `minPx` pixels from the
 *  last kept one, and the last point always (a four-hour trail is tens of thousands of rows;
 *  the screen shows a few hundred distinct pixels of it). */
export function decimate(points: Array<[number, number]>, minPx: number): Array<[number, number]> {
  const out: Array<[number, number]> = [];
  const min2 = minPx * minPx;
  for (let i = 0; i < points.length; i++) {
    const p = points[i];
    const last = out[out.length - 1];
    if (!last || i === points.length - 1 || (p[0] - last[0]) ** 2 + (p[1] - last[1]) ** 2 >= min2) out.push(p);
  }
  return out;
}

/** The last row at or before `t` (null when the trail starts later). Binary search. */
export function rowAt(trail: TrailRow[], t: number): TrailRow | null {
  let lo = 0;
  let hi = trail.length - 1;
  if (hi < 0 || trail[0][0] > t) return null;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (trail[mid][0] <= t) lo = mid;
    else hi = mid - 1;
  }
  return trail[lo];
}
