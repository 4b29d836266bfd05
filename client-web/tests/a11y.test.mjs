// axe-core (Deque's accessibility engine, run in Chromium) finds no violation on the page with
// every panel open: controls, stats overlay, clip box and its handles, an added isosurface,
// the colour map's legend, a bookmark, and a finished recording with its progress bar.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createRequire } from 'node:module';
import { withPage, settledPixels, frameCount } from './harness.mjs';

const axePath = createRequire(import.meta.url).resolve('axe-core/axe.min.js');

test('axe-core finds no violation with every panel open', async (t) => {
  await withPage('axe', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3&scale=0.25`);
    await settledPixels(page);
    let before = await frameCount(page);
    await page.locator('#stats-toggle').click();
    await page.locator('#clip-on').check();
    await page.locator('#surface-add').click();
    await page.selectOption('#cmap', 'viridis');
    await page.locator('#bm-name').fill('Start');
    await page.locator('#bm-save').click();
    await settledPixels(page, { from: before });
    await page.locator('#rec-to').fill('0.2');
    await page.selectOption('#rec-fps', '10');
    await page.locator('#record').click();
    await page.waitForFunction(() => /^Recorded/.test(document.getElementById('rec-status').textContent), null, { timeout: 60000 });
    for (const id of ['stats', 'legend', 'further-0', 'handle-min-x', 'rec-progress', 'rec-download', 'bookmarks', 'axes']) {
      assert.equal(await page.locator(`#${id}`).isVisible(), true, `#${id} is open`);
    }

    await page.addScriptTag({ path: axePath });
    const result = await page.evaluate(() => window.axe.run(document, { resultTypes: ['violations'] }));
    const found = result.violations.map((v) => `${v.id} (${v.impact}): ${v.help}\n  ${v.nodes.map((n) => n.target.join(' ')).join('\n  ')}`);
    t.diagnostic(`axe-core ${result.testEngine.version}: ${result.passes.length} rules passed`);
    assert.deepEqual(found, [], 'axe-core violations');
  });
});

test('axe-core finds no violation with a volume\'s controls greyed', async (t) => {
  await withPage('axe-volume', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=clouds&t=2&scale=0.25`);
    await settledPixels(page);
    await page.locator('#volume-note').waitFor();
    await page.addScriptTag({ path: axePath });
    const result = await page.evaluate(() => window.axe.run(document, { resultTypes: ['violations'] }));
    const found = result.violations.map((v) => `${v.id} (${v.impact}): ${v.help}\n  ${v.nodes.map((n) => n.target.join(' ')).join('\n  ')}`);
    t.diagnostic(`axe-core ${result.testEngine.version}: ${result.passes.length} rules passed`);
    assert.deepEqual(found, [], 'axe-core violations');
  });
});
