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
