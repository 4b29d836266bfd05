// The viewer in a real browser against the real server: a frame arrives and is not blank, and
// the camera controls (mouse drag, keyboard, touch pinch, reset, view up) and the isovalue
// slider change the picture.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, waitForFrames, settledPixels, meanAbsDiff, stddev, frameCount, drag } from './harness.mjs';

// Scene time pinned through the URL, so only our inputs change the picture.
const PINNED = '?scene=blobs&t=3';
// Mean absolute difference (0–255 per channel) above which two frames show different views.
// Re-rendering the same view gives 0 (still frames are lossless PNG); a 120-pixel orbit of
// the blobs scene moves several percent of the pixels by tens of levels (measured: > 10).
const CHANGED = 2;

test('the page shows a non-blank frame; a drag and the isovalue slider change it', async () => {
  await withPage('drag-and-slider', async ({ server, page }) => {
    await page.goto(server.url + PINNED);
    await waitForFrames(page, 1);
    assert.equal(await page.locator('#status').isHidden(), true, 'the waiting banner goes once a frame is shown');
    const first = await settledPixels(page);
    assert.ok(stddev(first) > 10, `the canvas shows a picture (grey-level stddev ${stddev(first).toFixed(1)})`);

    // The field's histogram is drawn behind the isovalue slider.
    await page.waitForFunction(() => Number(document.querySelector('canvas.histogram').dataset.samples) > 0);
    const histogram = await page.evaluate(() => window.isoray.surfaces.histogram);
    assert.equal(histogram.counts.length, 128);
    assert.equal(histogram.time, 3, 'for the time on screen');
    assert.ok(histogram.counts.some((c) => c > 0), 'with field values in the slider range');

    let before = await frameCount(page);
    await drag(page, 120, 30);
    const dragged = await settledPixels(page, { from: before });
    const dragDiff = meanAbsDiff(first, dragged);
    assert.ok(dragDiff > CHANGED, `a drag orbits the camera (mean abs diff ${dragDiff.toFixed(2)})`);

    before = await frameCount(page);
    await page.locator('#isovalue').fill('1.1');
    const thinner = await settledPixels(page, { from: before });
    const isoDiff = meanAbsDiff(dragged, thinner);
    assert.ok(isoDiff > CHANGED, `the isovalue slider changes the surface (mean abs diff ${isoDiff.toFixed(2)})`);
    await page.waitForURL((url) => Math.abs(Number(url.searchParams.get("iso")) - 1.1) < 0.01);
  });
});

test('keyboard, pan, touch pinch, view up and reset move the camera', async () => {
  await withPage('camera-controls', async ({ page, server }) => {
    await page.goto(server.url + PINNED);
    const home = await settledPixels(page);
    const distance0 = await page.evaluate(() => window.isoray.settings.cam.distance);

    // Keyboard: the canvas takes focus with Tab order and orbits with the arrow keys.
    await page.locator('#view').focus();
    let before = await frameCount(page);
    for (let i = 0; i < 6; i++) await page.keyboard.press('ArrowLeft');
    const turned = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(home, turned) > CHANGED, 'arrow keys orbit');

    before = await frameCount(page);
    await page.keyboard.press('Home');
    const reset = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(home, reset) < 0.5, `Home resets the view (diff ${meanAbsDiff(home, reset).toFixed(3)})`);

    // Right-drag pans: the target moves, the distance does not.
    before = await frameCount(page);
    await drag(page, 80, 0, { button: 'right' });
    const panned = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(home, panned) > CHANGED, 'a right-drag pans');
    const target = await page.evaluate(() => window.isoray.settings.cam.target);
    assert.ok(Math.hypot(...target) > 0.1, `the pan moved the target (${target})`);

    // Two-finger pinch outwards zooms in (touch events through the DevTools protocol).
    await page.click('#reset');
    // (At this window width the panel is below the view, and clicking Reset scrolled to it.)
    await page.locator('#view').scrollIntoViewIfNeeded();
    const box = await page.locator('#view').boundingBox();
    const cx = box.x + box.width / 2, cy = box.y + box.height / 2;
    const cdp = await page.context().newCDPSession(page);
    const touch = (type, spread) => cdp.send('Input.dispatchTouchEvent', {
      type,
      touchPoints: type === 'touchEnd' ? [] : [{ x: cx - spread, y: cy, id: 1 }, { x: cx + spread, y: cy, id: 2 }],
    });
    await touch('touchStart', 20);
    for (let s = 30; s <= 120; s += 15) await touch('touchMove', s);
    await touch('touchEnd', 0);
    await page.waitForFunction((d0) => window.isoray.settings.cam.distance < d0 * 0.6, distance0);

    // View up +z: the same eye position, a different up vector, so the picture rolls.
    await page.click('#reset');
    const reHome = await settledPixels(page);
    before = await frameCount(page);
    await page.selectOption('#up', '+z');
    const zUp = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(reHome, zUp) > CHANGED, 'choosing +Z as view up changes the picture');
    await page.waitForURL(/up=%2Bz/);
  });
});
