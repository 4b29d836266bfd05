// The viewer in a real browser against the real server: frames arrive, drag and slider
// change the picture, and the overlay's frame rate is the real one.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, waitForFrames, settledPixels, meanAbsDiff, stddev, frameCount } from './harness.mjs';

// Scene time pinned through the URL, so only our inputs change the picture.
const PINNED = '?scene=blobs&t=3';

test('page shows a frame; a drag and the isovalue slider change it', async () => {
  await withPage('drag-and-slider', async ({ server, page }) => {
    await page.goto(server.url + PINNED);
    await waitForFrames(page, 1);
    const first = await settledPixels(page);
    assert.ok(stddev(first) > 10, `the canvas shows a picture (grey-level stddev ${stddev(first).toFixed(1)})`);

    const box = await page.locator('#view').boundingBox();
    await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
    await page.mouse.down();
    await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 + 30, { steps: 6 });
    await page.mouse.up();
    const dragged = await settledPixels(page);
    const dragDiff = meanAbsDiff(first, dragged);
    assert.ok(dragDiff > 2, `a drag orbits the camera (mean abs diff ${dragDiff.toFixed(2)})`);

    await page.locator('#isovalue').fill('1.1');
    const thinner = await settledPixels(page);
    const isoDiff = meanAbsDiff(dragged, thinner);
    assert.ok(isoDiff > 2, `the isovalue slider changes the surface (mean abs diff ${isoDiff.toFixed(2)})`);
  });
});

test('the stats overlay shows the frame rate the page really receives', async () => {
  await withPage('stats-fps', async ({ server, page }) => {
    await page.goto(server.url + '?scene=blobs');
    await waitForFrames(page, 3);
    // Count frames over three seconds and compare with what the overlay said meanwhile.
    const shown = [];
    const before = await frameCount(page);
    const t0 = Date.now();
    for (let i = 0; i < 6; i++) {
      await page.waitForTimeout(500);
      const text = await page.locator('#stats').textContent();
      shown.push(Number(/fps\s+(\d+)/.exec(text)[1]));
    }
    const observed = (await frameCount(page) - before) / ((Date.now() - t0) / 1000);
    const mean = shown.slice(2).reduce((a, b) => a + b, 0) / (shown.length - 2);
    assert.ok(observed > 1, `frames arrive while the scene animates (${observed.toFixed(1)} fps)`);
    assert.ok(Math.abs(mean - observed) <= Math.max(2, observed * 0.25),
      `overlay fps ${mean.toFixed(1)} vs observed ${observed.toFixed(1)}`);
  });
});
