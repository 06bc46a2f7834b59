// SPDX-License-Identifier: MIT
// axe-core (npm, run inside the page) for the browser tests: the violations of a page rated
// serious or critical under WCAG 2.1 A/AA, AAA (enhanced colour contrast, 7:1: a tablet read
// outdoors in daylight) and axe's best practices. The page needs `bypassCSP: true`.
import { createRequire } from 'node:module';

const axePath = createRequire(import.meta.url).resolve('axe-core/axe.min.js');
const tags = ['wcag2a', 'wcag2aa', 'wcag2aaa', 'wcag21a', 'wcag21aa', 'best-practice'];

async function run(page) {
  await page.addScriptTag({ path: axePath });
  return page.evaluate((values) => window.axe.run(document, { runOnly: { type: 'tag', values } }), tags);
}

// Fails (through `fail`) on a serious or critical violation; returns the others in words.
export async function checkAccessibility(page, where, fail) {
  const result = await run(page);
  const bad = result.violations.filter((v) => v.impact === 'serious' || v.impact === 'critical');
  if (bad.length > 0) {
    fail(`${where}: ${bad.length} accessibility violation(s): ` + bad.map((v) =>
      `${v.id} (${v.impact}): ${v.nodes.slice(0, 3).map((n) => n.target.join(' ')).join(', ')} — ${v.help}`).join('; '));
  }
  return result.violations.map((v) => `${v.id} (${v.impact})`).join(', ') || 'none';
}

// The check itself: a button without a name must be reported as critical.
export async function checkTheChecker(browser, fail) {
  const probe = await browser.newPage();
  await probe.setContent('<!doctype html><html lang="en"><title>t</title><main><h1>t</h1><button></button></main></html>');
  const result = await run(probe);
  if (!result.violations.some((v) => v.id === 'button-name' && v.impact === 'critical')) {
    fail('axe-core did not report a button without a name');
  }
  await probe.close();
}
