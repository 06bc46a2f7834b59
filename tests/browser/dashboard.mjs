// The dashboard of `trailmark serve` in Debian's Chromium (headless, through playwright-core):
// after a few seconds of replay the page lists the right firefighters near the positions the
// API reports, a click selects one, and a screenshot is written.
// usage: node dashboard.mjs URL TOKEN EXPECTED_AGENTS SCREENSHOT.png
import { chromium } from 'playwright-core';

const [url, token, expected, shot] = process.argv.slice(2);
const fail = (msg) => { console.error('FAIL: ' + msg); process.exit(1); };
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
                                        args: ['--no-sandbox', '--headless=new'] });
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  await page.goto(`${url}/?token=${token}`);
  await page.waitForSelector('#list .node', { timeout: 10000 });
  await page.waitForTimeout(3000);
  const names = await page.$$eval('#list .node', (els) => els.map((e) => e.dataset.id));
  if (names.length !== Number(expected)) fail(`expected ${expected} firefighters, the page lists ${names.join(', ')}`);
  // The page shows the positions the API gives (within what moves in half a second of replay).
  const state = await (await fetch(`${url}/api/state`, { headers: { Authorization: `Bearer ${token}` } })).json();
  for (const el of await page.$$eval('#list .node', (els) => els.map((e) => e.textContent))) {
    const m = el.match(/^(\S+): \((-?[\d.]+), (-?[\d.]+)\) m$/);
    if (!m) fail(`unexpected entry '${el}'`);
    const node = state.nodes.find((n) => n.id === m[1]);
    if (!node) fail(`${m[1]} is not in /api/state`);
    const d = Math.hypot(node.x - Number(m[2]), node.y - Number(m[3]));
    if (d > 15) fail(`${m[1]} shown ${d.toFixed(1)} m from the API position`);
  }
  await page.click(`#list .node[data-id="${names[0]}"]`);
  await page.waitForTimeout(700);
  const selected = await page.$$eval('#list .node.sel', (els) => els.map((e) => e.dataset.id));
  if (selected.length !== 1 || selected[0] !== names[0]) fail(`click did not select ${names[0]}: ${selected}`);
  await page.screenshot({ path: shot });
  console.log(`dashboard: ${names.length} firefighters (${names.join(', ')}), ${names[0]} selected, screenshot ${shot}`);
} finally {
  await browser.close();
}
