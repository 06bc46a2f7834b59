// SPDX-License-Identifier: MIT
// The HTML report's map in Debian's Chromium (issue 28, item 5): drawn at true scale — a metre
// as long east as north — in a wide and in a tall window, after zooming with the wheel and the
// buttons and after a drag; "fit" returns to the whole mission; a layer unticked in the legend
// is hidden; no error in the console.
// usage: node report.mjs REPORT.html [SCREENSHOT.png]
import { chromium } from 'playwright-core';
import { pathToFileURL } from 'node:url';

const [report, shot] = process.argv.slice(2);
const fail = (msg) => { console.error('FAIL: ' + msg); process.exit(1); };
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
                                        args: ['--no-sandbox', '--headless=new'] });
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 700 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(pathToFileURL(report).href);
  await page.waitForSelector('#map g[data-label="walls"]');
  // Screen pixels per metre along x and along y (the root group flips y).
  const scales = () => page.evaluate(() => {
    const m = document.querySelector('#map > g').getScreenCTM();
    return { x: Math.hypot(m.a, m.b), y: Math.hypot(m.c, m.d), flipped: m.d < 0, view: window.trailmarkReportMap.view() };
  });
  const trueScale = async (what) => {
    const s = await scales();
    if (!(s.x > 0) || Math.abs(s.x - s.y) > 1e-6 * s.x || !s.flipped) fail(`${what}: ${s.x} px/m east, ${s.y} px/m north (flipped ${s.flipped})`);
    return s;
  };
  const home = await trueScale('wide window');
  await page.setViewportSize({ width: 600, height: 1000 });
  await page.waitForTimeout(100);
  await trueScale('tall window');
  await page.setViewportSize({ width: 1280, height: 700 });
  const box = await page.$eval('#map', (e) => e.getBoundingClientRect().toJSON());
  await page.mouse.move(box.x + box.width * 0.3, box.y + box.height * 0.4);
  await page.mouse.wheel(0, -600);
  await page.waitForTimeout(100);
  const zoomed = await trueScale('after the wheel');
  if (!(zoomed.x > 1.5 * home.x)) fail(`the wheel did not zoom in: ${home.x} -> ${zoomed.x} px/m`);
  await page.click('#zin');
  const more = await trueScale('after +');
  if (!(more.x > zoomed.x)) fail('+ did not zoom in');
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 100, box.y + box.height / 2 + 50, { steps: 5 });
  await page.mouse.up();
  const dragged = await trueScale('after a drag');
  if (Math.abs(dragged.view[0] - more.view[0]) < 1e-6) fail('a drag did not pan');
  await page.click('#zfit');
  const back = await scales();
  if (back.view.join() !== home.view.join()) fail(`fit: ${back.view} != ${home.view}`);
  // The legend hides a layer.
  const first = await page.$eval('#legend label', (e) => e.textContent);
  await page.click('#legend label input');
  const hidden = await page.$eval('#map g[data-label]', (g) => getComputedStyle(g).display);
  if (hidden !== 'none') fail(`unticking '${first}' left it drawn (${hidden})`);
  await page.click('#legend label input');
  // Layers hidden until ticked (map matching's search patterns): not drawn, then drawn.
  const initially = await page.$$eval('#legend label input', (boxes) => boxes.map((b) => b.checked));
  const ticked = [];
  for (let i = 0; i < initially.length; ++i) {
    if (initially[i]) continue;
    const layer = `#map > g > g:nth-child(${i + 1})`;
    const label = await page.$eval(`#legend label:nth-child(${i + 1})`, (e) => e.textContent);
    if (await page.$eval(layer, (g) => getComputedStyle(g).display) !== 'none') fail(`'${label}' drawn before it is ticked`);
    await page.click(`#legend label:nth-child(${i + 1}) input`);
    const shown = await page.$eval(layer, (g) => ({ display: getComputedStyle(g).display, items: g.childElementCount, label: g.dataset.label }));
    if (shown.display === 'none' || shown.items === 0 || shown.label !== label) fail(`ticking '${label}' did not draw it (${JSON.stringify(shown)})`);
    ticked.push(`${label}: ${shown.items}`);
  }
  if (shot) {
    await page.$eval('h2 + p.note + .mapwrap', (e) => e.scrollIntoView());
    await page.$eval('.mapwrap', (e) => e.parentElement.querySelector('h2:nth-of-type(2)')?.scrollIntoView());
    await page.screenshot({ path: shot, fullPage: false });
  }
  if (errors.length) fail(`console errors: ${errors.join(' | ')}`);
  console.log(`report: true scale (${home.x.toFixed(2)} px/m both ways, wide and tall), wheel, buttons, drag and fit; legend hides '${first}'${ticked.length ? '; ticked on: ' + ticked.join(', ') : ''}; no console error`);
} finally {
  await browser.close();
}
