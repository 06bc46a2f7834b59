// SPDX-License-Identifier: MIT
// Pure helpers (no DOM): the 95 % ellipse of a 2-D covariance, a running box of the trails,
// lookups in a trail by time. (The view itself is Leaflet's: map.ts.)
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

/** A box that only grows: the trails' extent kept as rows arrive, so that "fit all" costs the
 *  same after four hours as after a minute. */
export class Bounds {
  minx = Infinity;
  maxx = -Infinity;
  miny = Infinity;
  maxy = -Infinity;
  add(x: number, y: number): void {
    if (Number.isFinite(x)) (this.minx = Math.min(this.minx, x)), (this.maxx = Math.max(this.maxx, x));
    if (Number.isFinite(y)) (this.miny = Math.min(this.miny, y)), (this.maxy = Math.max(this.maxy, y));
  }
  /** Its corners (nothing when empty). */
  corners(xs: number[], ys: number[]): void {
    if (this.minx <= this.maxx) xs.push(this.minx, this.maxx);
    if (this.miny <= this.maxy) ys.push(this.miny, this.maxy);
  }
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

/** A trail kept within `maxRows` for a long incident: when longer, the rows before the last
 *  `keepRecent` are halved (every other one, from the first), so older parts grow sparser and
 *  the recent part stays whole. Null when nothing is to be dropped. Amortized: a trail is
 *  thinned once every (maxRows - keepRecent) / 2 rows appended. */
export function thinTrail(rows: TrailRow[], maxRows: number, keepRecent: number): TrailRow[] | null {
  if (rows.length <= maxRows) return null;
  const cut = Math.max(0, rows.length - keepRecent);
  const out: TrailRow[] = [];
  for (let i = 0; i < cut; i += 2) out.push(rows[i]);
  for (let i = cut; i < rows.length; i++) out.push(rows[i]);
  return out;
}
