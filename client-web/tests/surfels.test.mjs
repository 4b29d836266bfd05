// A surfel demo in the browser (deforming-point-sampled-surfaces.txt): the small clipped-cubes
// scene shows frames, animates while the time runs, and a drag orbits the camera.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, waitForFrames, settledPixels, canvasPixels, meanAbsDiff, stddev, frameCount, drag } from './harness.mjs';

// Mean absolute difference (0–255 per channel) above which two frames differ: re-rendering the
// same still view gives 0 (lossless still frames).
const CHANGED = 1;

test('a surfel demo shows frames, animates, and a drag changes the image', async (t) => {
  await withPage('surfels', async ({ server, page }) => {
    const listed = await (await fetch(`${server.url}api/v1/scenes`)).json();
    const demo = listed.scenes.find((s) => s.id === 'surfel-heads');
    assert.equal(demo?.kind, 'surfels', 'the surfel demos are listed as surfels');

    // Live: the simulation runs, so frames keep coming and the picture moves.
    await page.goto(`${server.url}?scene=surfel-heads&scale=0.25`);
    await waitForFrames(page, 2, { timeout: 60000 });
    const a = await canvasPixels(page);
    assert.ok(stddev(a) > 5, `the canvas shows the cubes (stddev ${stddev(a).toFixed(1)})`);
    const t0 = await page.evaluate(() => window.isoray.view.lastHeader.sceneTime);
    await page.waitForFunction((t0) => window.isoray.view.lastHeader.sceneTime > t0 + 0.5, t0, { timeout: 60000 });
    const b = await canvasPixels(page, [a.width, a.height]);
    const moved = meanAbsDiff(a, b);
    t.diagnostic(`animation: mean abs diff ${moved.toFixed(2)} over half a second of scene time`);
    assert.ok(moved > CHANGED, `the cubes move (mean abs diff ${moved.toFixed(2)})`);

    // Pinned time: only the drag changes the picture.
    await page.goto(`${server.url}?scene=surfel-heads&t=1.5&scale=0.25`);
    const still = await settledPixels(page, { timeout: 60000 });
    const before = await frameCount(page);
    await drag(page, 120, 20);
    const dragged = await settledPixels(page, { from: before, timeout: 60000 });
    const diff = meanAbsDiff(still, dragged);
    assert.ok(diff > CHANGED, `a drag orbits the camera (mean abs diff ${diff.toFixed(2)})`);
  });
});

test('a surfel scene offers no isovalue, further isosurfaces or colour map; a metaball scene does', async () => {
  await withPage('surfels-controls', async ({ server, page }) => {
    const infos = [];
    const histograms = [];
    page.on('websocket', (ws) => ws.on('framereceived', ({ payload }) => {
      if (typeof payload === 'string' && payload.includes('"type":"info"')) infos.push(JSON.parse(payload));
    }));
    page.on('request', (r) => { if (r.url().includes('/histogram')) histograms.push(r.url()); });
    const shown = () => page.evaluate(() => ['h-surfaces', 'h-colors']
      .map((id) => document.getElementById(id).closest('section').checkVisibility()));

    await page.goto(`${server.url}?scene=surfel-heads&t=1.5&scale=0.25`);
    await waitForFrames(page, 1, { timeout: 60000 });
    assert.equal(infos.at(-1).scalar_field, false, 'the server says a surfel surface has no field');
    assert.deepEqual(await shown(), [false, false], 'no isovalue or colour-map controls');
    // The controls of the panel that stay: time and effects.
    assert.ok(await page.locator('#h-time').isVisible());

    await page.goto(`${server.url}?scene=blobs&t=1.5&scale=0.25`);
    await waitForFrames(page, 1, { timeout: 60000 });
    assert.equal(infos.at(-1).scalar_field, true);
    assert.deepEqual(await shown(), [true, true], 'a metaball scene has both');
    await page.waitForFunction(() => document.querySelector('#surfaces canvas.histogram')?.dataset.bins === '128');
    assert.ok(histograms.length > 0 && histograms.every((u) => u.includes('/scenes/blobs/')), `histograms asked for blobs only: ${histograms}`);
  });
});
