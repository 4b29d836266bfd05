// The view survives: reloading the URL restores it, and when the server stops and comes back
// the page shows that it is reconnecting, then streams the same view again.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, settledPixels, meanAbsDiff, frameCount, drag, waitForFrames } from './harness.mjs';

// Still frames are lossless and the engine deterministic, so the same view renders the same
// pixels; the URL keeps camera values to 6 decimals, which can move an edge pixel or two.
const SAME = 0.5;
const CHANGED = 2;

async function changeEverything(page) {
  let before = await frameCount(page);
  await drag(page, -90, 40);
  await settledPixels(page, { from: before });
  before = await frameCount(page);
  await drag(page, 30, -20, { shift: true });
  await settledPixels(page, { from: before });
  before = await frameCount(page);
  await page.locator('#isovalue').fill('0.8');
  await settledPixels(page, { from: before });
  before = await frameCount(page);
  await page.locator('#time').fill('7.5');
  return settledPixels(page, { from: before });
}

test('a reload of the URL restores the same view', async () => {
  await withPage('reload', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3`);
    const start = await settledPixels(page);
    const changed = await changeEverything(page);
    assert.ok(meanAbsDiff(start, changed) > CHANGED, 'the view changed before the reload');
    await page.waitForURL((url) => url.searchParams.get('t') === '7.5');
    const url = page.url();
    assert.match(url, /cam=/);
    assert.ok(Math.abs(Number(new URL(url).searchParams.get('iso')) - 0.8) < 0.01, 'the isovalue is in the URL');

    await page.reload();
    const restored = await settledPixels(page);
    assert.equal(page.url(), url, 'the reload keeps the URL');
    const diff = meanAbsDiff(changed, restored);
    assert.ok(diff < SAME, `the reloaded page shows the same view (mean abs diff ${diff.toFixed(3)})`);

    // And the URL alone, in a fresh page, gives the same picture too.
    const fresh = await page.context().newPage();
    await fresh.goto(url);
    const shared = await settledPixels(fresh);
    assert.ok(meanAbsDiff(changed, shared) < SAME, `a shared URL shows the same view (diff ${meanAbsDiff(changed, shared).toFixed(3)})`);
    await fresh.close();
  });
});

test('stopping and restarting the server shows the reconnect state, then the same view again', async (t) => {
  await withPage('reconnect', async ({ server, page, network, startServer }) => {
    await page.goto(`${server.url}?scene=blobs&t=3`);
    await settledPixels(page);
    const view = await changeEverything(page);

    // Stop the server: the page says so and keeps trying. The browser itself logs each
    // refused connection as a console error; those (and only those) are expected now.
    network.expectNetworkErrors = true;
    await server.stop({ keepData: true });
    await page.waitForFunction(() => /Disconnected|Reconnecting/.test(document.getElementById('status-text').textContent)
      && !document.getElementById('status').hidden, null, { timeout: 10000 });
    const banner = await page.locator('#status-text').textContent();
    assert.match(banner, /server shutting down|Reconnecting|Disconnected/, `banner: ${banner}`);
    await page.waitForFunction(() => document.body.dataset.connection === 'waiting' || document.body.dataset.connection === 'connecting');
    await page.waitForTimeout(1500); // a few failed attempts with back-off

    const before = await frameCount(page);
    await startServer({ port: server.port, dataDir: server.dataDir });
    await waitForFrames(page, 1, { from: before, timeout: 15000 });
    network.expectNetworkErrors = false;
    const again = await settledPixels(page, { from: before });
    assert.equal(await page.locator('#status').isHidden(), true, 'the banner is gone once frames come again');
    const diff = meanAbsDiff(view, again);
    assert.ok(diff < SAME, `after the restart the page shows the same view (mean abs diff ${diff.toFixed(3)})`);
    t.diagnostic(`browser network errors while the server was down: ${network.expected.length} (${network.expected[0] ?? 'none'})`);
  });
});
