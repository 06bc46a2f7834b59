// SPDX-License-Identifier: MIT
// The dashboard's floor selector (issue 26) in Debian's Chromium: a replayed multi-floor mission
// lists the plan's four levels (the ground floor shown first); picking a firefighter shows the
// floor /api/state gives it; choosing another floor from the selector draws that level's walls
// (the canvas changes) and marks firefighters on other floors with their floor in the list; the
// timeline dragged back shows the floors of then; the history refresh asks only for what is new;
// axe-core finds no serious accessibility violation with another floor shown.
// usage: node floors.mjs URL TOKEN SCREENSHOT.png
import { chromium } from 'playwright-core';
import { checkAccessibility } from './a11y.mjs';

const [url, token, shot] = process.argv.slice(2);
const fail = (msg) => { console.error('FAIL: ' + msg); process.exit(1); };
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
                                        args: ['--no-sandbox', '--headless=new'] });
const api = async (path) => (await fetch(`${url}${path}`, { headers: { Authorization: `Bearer ${token}` } })).json();
try {
  const plan = await api('/api/floorplan');
  const levels = (plan.levels ?? []).map((l) => l.level).sort((a, b) => a - b);
  if (levels.join(',') !== '-1,0,1,2') fail(`/api/floorplan levels: ${JSON.stringify(levels)}`);
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 }, bypassCSP: true });
  // The periodic refresh asks only for what came after its last fetch (issue 28).
  const refreshes = [];
  page.on('response', async (r) => {
    if (r.url().includes('/api/history?since=')) refreshes.push({ status: r.status(), body: await r.json().catch(() => null) });
  });
  await page.goto(`${url}/?token=${token}`);
  await page.waitForSelector('#list .node', { timeout: 10000 });
  if (await page.$eval('#floorbar', (e) => e.hidden)) fail('no floor selector for a four-level plan');
  const options = await page.$$eval('#floor option', (els) => els.map((e) => e.value));
  if (options.join(',') !== '2,1,0,-1') fail(`selector options ${options}`);
  if ((await page.$eval('#floor', (e) => e.value)) !== '0') fail('the ground floor is not shown first');
  // The view fits the building and the walks (about 30 m across), wherever the frame's origin
  // is: at least 8 px per metre on this screen.
  const scale = await page.evaluate(() => window.trailmarkView?.scale ?? 0);
  if (!(scale >= 8)) fail(`the map is drawn at ${scale} px/m: the view does not fit the building`);
  // Wait until ff1 has climbed (the replay runs at 20x), then pick it: its floor is shown.
  let ff1 = null;
  for (let i = 0; i < 60; ++i) {
    const state = await api('/api/state');
    ff1 = state.nodes.find((n) => n.id === 'ff1');
    if (ff1 && ff1.floor >= 1) break;
    await page.waitForTimeout(500);
  }
  if (!ff1 || !(ff1.floor >= 1)) fail(`ff1 never reached an upper floor: ${JSON.stringify(ff1)}`);
  await page.click('#list .node[data-id="ff1"]');
  await page.waitForTimeout(300);
  const shownFloor = Number(await page.$eval('#floor', (e) => e.value));
  if (shownFloor < 1) fail(`picking ff1 (floor ${ff1.floor}) shows floor ${shownFloor}`);
  // Another floor draws other walls: the basement's plan layer replaces the shown one.
  await page.click('#live');  // stop following a selection change, keep live
  const before = await page.evaluate(() => window.trailmarkMap);
  await page.selectOption('#floor', '-1');
  await page.waitForTimeout(200);
  const after = await page.evaluate(() => window.trailmarkMap);
  if (after.planLevel !== -1 || before.planLevel === -1) fail(`the plan drawn: level ${before.planLevel} then ${after.planLevel}`);
  const basement = plan.levels.find((l) => l.level === -1).walls.length;
  if (after.planSegments !== basement) fail(`the basement has ${basement} walls, the map draws ${after.planSegments}`);
  if ((await page.$eval('#floor', (e) => e.value)) !== '-1') fail('the selector did not keep the basement');
  await page.screenshot({ path: shot });
  const others = await checkAccessibility(page, 'floor selector, another floor shown', fail);
  // Replay: the timeline dragged back to the start shows ff1 where it was, on the ground floor
  // (the history carries each row's floor).
  await page.$eval('#timeline', (el) => { el.value = el.min; el.dispatchEvent(new Event('input')); });
  await page.waitForTimeout(300);
  const detail = await page.$eval('#list .node[data-id="ff1"] small', (e) => e.textContent);
  if (!/floor 0$/.test(detail)) fail(`ff1 at the start of the timeline: '${detail}'`);
  for (let i = 0; i < 30 && refreshes.length === 0; ++i) await page.waitForTimeout(500);
  if (refreshes.length === 0) fail('no /api/history?since= refresh within 15 s');
  const r = refreshes[0];
  if (r.status !== 200 || !r.body || typeof r.body.since !== 'number') fail(`history refresh: ${JSON.stringify(r).slice(0, 200)}`);
  for (const rows of Object.values(r.body.trails)) {
    if (rows.some((row) => !(row[0] > r.body.since))) fail('a refresh row older than its since');
  }
  console.log(`floors: levels ${options.join(', ')}; ff1 picked on floor ${shownFloor}; basement drawn; axe-core: no serious violation (others: ${others}); screenshot ${shot}`);
} finally {
  await browser.close();
}
