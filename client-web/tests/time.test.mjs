// Time controls against the real server: scrubbing a demo's time, and a pushed scene's steps
// in the scene picker, scrubbed, played, and followed live while a "simulation" pushes more.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, waitForFrames, settledPixels, meanAbsDiff, frameCount, api, canvasPixels } from './harness.mjs';

const CHANGED = 2; // see viewer.test.mjs

test('scrubbing time changes the picture, and play advances it', async () => {
  await withPage('time-scrub', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3`);
    const at3 = await settledPixels(page);
    assert.match(await page.locator('#time-out').textContent(), /^3 s/);

    let before = await frameCount(page);
    await page.locator('#time').fill('9');
    const at9 = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(at3, at9) > CHANGED, `scrubbing from 3 s to 9 s changes the picture (diff ${meanAbsDiff(at3, at9).toFixed(2)})`);
    await page.waitForURL(/t=9(&|$)/);
    // The histogram behind the isovalue slider follows the time on screen.
    await page.waitForFunction(() => window.isoray.surfaces.histogram && window.isoray.surfaces.histogram.time === 9);

    // Play pins successive times; pause stops there.
    before = await frameCount(page);
    await page.click('#play');
    await waitForFrames(page, 4, { from: before });
    await page.click('#play');
    const paused = await page.evaluate(() => window.isoray.settings.time);
    assert.ok(paused > 9, `playing moved the time on (now ${paused} s)`);
    assert.equal(await page.locator('#play').getAttribute('aria-pressed'), 'false');

    // Live follows the server's clock again.
    await page.click('#live');
    await page.waitForFunction(() => window.isoray.settings.time === null);
    await waitForFrames(page, 3);
    // The viewer writes the URL at most every 100 ms (app.js `saved`), from the settings at
    // the time of writing, so it follows the switch to live on its own clock, not the frames':
    // wait for it rather than read it after some frames.
    await page.waitForURL((url) => !url.searchParams.has('t'), { timeout: 5000 });
    // No stale write pins an old time afterwards (a shared link would reopen the past).
    await waitForFrames(page, 3);
    assert.doesNotMatch(page.url(), /[?&]t=/, 'live is the default, so the URL pins no time');
    assert.equal(await page.evaluate(() => window.isoray.settings.time), null, 'still live');
  });
});

// Four blobs whose positions depend on the step, so each step looks different.
function step(k, n = 6) {
  const positions = [];
  for (let i = 0; i < n; i++) {
    const a = (i / n) * 2 * Math.PI + k * 0.7;
    positions.push([1.6 * Math.cos(a), 0.5 * Math.sin(k + i), 1.6 * Math.sin(a)]);
  }
  return { positions, radii: positions.map(() => 0.9) };
}

test('a pushed scene: the picker shows its steps, the scrubber walks them, live follows new pushes', async () => {
  await withPage('stored-steps', async ({ server, page }) => {
    const created = await api(server, 'POST', '/api/v1/scenes', {
      kind: 'metaballs',
      name: 'Pushed ring',
      camera: { eye: [0, 3, 7], target: [0, 0, 0] },
    });
    const id = created.scene.id;
    const token = created.write_token;
    for (let k = 0; k < 3; k++) await api(server, 'PUT', `/api/v1/scenes/${id}/steps/${k}?time=${k * 0.5}`, step(k), token);

    await page.goto(`${server.url}?scene=${id}&t=0`);
    const option = page.locator(`#scene option[value="${id}"]`);
    assert.match(await option.textContent(), /Pushed ring \(metaballs · 6 balls · 3 time steps\)/);
    const step0 = await settledPixels(page);
    assert.match(await page.locator('#time-out').textContent(), /step 0 \(1 of 3, t = 0\)/);

    let before = await frameCount(page);
    await page.locator('#time').fill('2');
    const step2 = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(step0, step2) > CHANGED, `step 2 differs from step 0 (diff ${meanAbsDiff(step0, step2).toFixed(2)})`);
    assert.equal(await page.evaluate(() => window.isoray.settings.time), 1, 'the scrubber pins the step\'s time');

    // Live: the newest step, and a step pushed while watching appears without a reload.
    await page.click('#live');
    await waitForFrames(page, 2);
    // Frames of a live view may come at any resolution the server picks; compare them
    // resampled to one size.
    const liveBefore = await canvasPixels(page, [160, 120]);
    await api(server, 'PUT', `/api/v1/scenes/${id}/steps/3?time=1.5`, step(7), token);
    await page.waitForFunction(() => /step 3 \(4 of 4, t = 1\.50\)/.test(document.getElementById('time-out').textContent), null, { timeout: 10000 });
    before = await frameCount(page);
    await waitForFrames(page, 2, { from: before });
    const liveAfter = await canvasPixels(page, [160, 120]);
    assert.ok(meanAbsDiff(liveBefore, liveAfter) > CHANGED, `the pushed step shows up live (diff ${meanAbsDiff(liveBefore, liveAfter).toFixed(2)})`);
    const live = await page.evaluate(() => window.isoray.settings.time);
    assert.equal(live, null, 'still following live');
  });
});
