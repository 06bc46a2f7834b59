// SPDX-License-Identifier: MIT
// The dashboard over a whole incident (issue 28, item 2): a 4-hour, 20-firefighter incident
// replayed fast into Debian's Chromium. Measured near the start (mission time 20 min) and near
// the end (3 h 50 min): the JS heap after a garbage collection, and the frame times over 3 s
// (requestAnimationFrame intervals while live messages arrive). Asserted: no error in the
// console, a heap within the stated limit and not growing with the incident, frame times at the
// end within the stated limit and as at the start, history refreshes of bounded size.
// usage: node soak.mjs URL TOKEN [JSON_OUT]
import { chromium } from 'playwright-core';
import { writeFileSync } from 'node:fs';

const [url, token, out] = process.argv.slice(2);
// The stated limits (docs/server.md): the heap (MB) at the end, its growth from the start
// (MB), the 95th percentile of the frame time (ms) at either end, and its growth from the start
// (ms: two frames at 60 Hz, the granularity of requestAnimationFrame).
const LIMITS = { heap_mb: 64, heap_growth_mb: 32, frame_p95_ms: 100, frame_p95_growth_ms: 34 };
const fail = (msg) => { console.error('FAIL: ' + msg); process.exit(1); };
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox', '--headless=new', '--enable-precise-memory-info', '--js-flags=--expose-gc'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 }, bypassCSP: true });
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  const refreshes = [];
  page.on('response', async (r) => {
    if (r.url().includes('/api/history?since=')) refreshes.push((await r.body().catch(() => Buffer.alloc(0))).length);
  });
  await page.goto(`${url}/?token=${token}`);
  await page.waitForFunction(() => document.querySelectorAll('#list .node').length === 20, null, { timeout: 30000 });
  const missionTime = () => page.$eval('#clock', (e) => Number((e.textContent.match(/([\d.]+) s$/) || [])[1] || 0));
  const waitFor = async (t) => {
    for (let i = 0; i < 600 && (await missionTime()) < t; ++i) await page.waitForTimeout(500);
    if ((await missionTime()) < t) fail(`the replay did not reach ${t} s (at ${await missionTime()} s)`);
  };
  const sample = () => page.evaluate(async () => {
    window.gc?.();
    const heap = performance.memory.usedJSHeapSize / 1048576;
    const frames = await new Promise((resolve) => {
      const d = [];
      let last = performance.now();
      const t0 = last;
      const tick = (now) => {
        d.push(now - last);
        last = now;
        if (now - t0 < 3000) requestAnimationFrame(tick);
        else resolve(d);
      };
      requestAnimationFrame(tick);
    });
    frames.sort((a, b) => a - b);
    const m = window.trailmarkMap;
    let rows = 0;
    for (const id of Array.from(document.querySelectorAll('#list .node')).map((e) => e.dataset.id)) rows += m.trailPoints(id);
    return { heap_mb: heap, frames: frames.length, frame_p95_ms: frames[Math.floor(0.95 * (frames.length - 1))],
             frame_max_ms: frames[frames.length - 1], trail_points: rows, appends: m.appends, rebuilds: m.rebuilds };
  });
  await waitFor(1200);
  const start = { mission_s: await missionTime(), ...(await sample()) };
  await waitFor(4 * 3600 - 600);
  const end = { mission_s: await missionTime(), ...(await sample()) };
  const result = { limits: LIMITS, start, end, history_refreshes: refreshes.length,
                   largest_refresh_kb: Math.max(0, ...refreshes) / 1024, console_errors: errors };
  if (out) writeFileSync(out, JSON.stringify(result, null, 2) + '\n');
  console.log(`soak: ${JSON.stringify(result)}`);
  if (errors.length) fail(`console errors: ${errors.slice(0, 5).join(' | ')}`);
  if (!(end.heap_mb <= LIMITS.heap_mb)) fail(`heap ${end.heap_mb.toFixed(1)} MB at the end (limit ${LIMITS.heap_mb})`);
  if (!(end.heap_mb - start.heap_mb <= LIMITS.heap_growth_mb)) fail(`heap grew ${(end.heap_mb - start.heap_mb).toFixed(1)} MB`);
  for (const s of [start, end]) {
    if (!(s.frame_p95_ms <= LIMITS.frame_p95_ms)) fail(`frame time p95 ${s.frame_p95_ms.toFixed(1)} ms at ${s.mission_s} s`);
  }
  if (!(end.frame_p95_ms <= start.frame_p95_ms + LIMITS.frame_p95_growth_ms)) {
    fail(`frame time p95 ${start.frame_p95_ms.toFixed(1)} ms at the start, ${end.frame_p95_ms.toFixed(1)} ms at the end`);
  }
  // A refresh is bounded by the server's max_rows (3,000 rows per firefighter, ~110 bytes each)
  // however long the incident: at 120x, ten seconds of wall time are twenty minutes of trails.
  const bound_kb = (20 * 3000 * 140) / 1024;
  if (result.largest_refresh_kb > bound_kb) fail(`a history refresh of ${result.largest_refresh_kb.toFixed(0)} kB (bound ${bound_kb.toFixed(0)} kB)`);
} finally {
  await browser.close();
}
