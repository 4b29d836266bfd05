// Orientation and views that survive: the axes widget turns with the camera, "reset to scene
// camera" returns to the scene's own view, named bookmarks live in the URL and bring their view
// back, and "copy link" puts the page's address on the clipboard.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, settledPixels, meanAbsDiff, frameCount, drag } from './harness.mjs';

const SAME = 0.5; // see state.test.mjs
const CHANGED = 2; // see viewer.test.mjs

const camOf = (url) => new URL(url).searchParams.get('cam')?.split(',').map(Number) ?? null;

/**
 * Where world axis k points on screen (right, down) for an orbit camera with y up at `yaw`,
 * `pitch`: the textbook look-at basis, written here apart from the client's camera.js.
 */
function expectedAxes(yaw, pitch) {
  const dir = [Math.cos(pitch) * Math.sin(yaw), Math.sin(pitch), Math.cos(pitch) * Math.cos(yaw)];
  const forward = dir.map((v) => -v);
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const unit = (a) => { const n = Math.hypot(...a); return a.map((v) => v / n); };
  const right = unit(cross(forward, [0, 1, 0]));
  const up = cross(right, forward);
  return [0, 1, 2].map((k) => [right[k], -up[k]]);
}

async function widgetAxes(page) {
  return page.locator('#axes line').evaluateAll((lines) => Object.fromEntries(
    lines.map((l) => [l.dataset.axis, [Number(l.dataset.dx), Number(l.dataset.dy)]])));
}

test('the orientation axes turn with the camera, and reset returns to the scene camera', async (t) => {
  await withPage('axes-and-reset', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3&scale=0.5`);
    const home = await settledPixels(page);
    await page.waitForURL(/cam=/);
    const homeCam = camOf(page.url());
    const check = async (cam) => {
      const got = await widgetAxes(page);
      const want = expectedAxes(cam[0], cam[1]);
      ['x', 'y', 'z'].forEach((axis, k) => {
        for (const c of [0, 1]) assert.ok(Math.abs(got[axis][c] - want[k][c]) < 0.01, `${axis} axis at yaw ${cam[0]}, pitch ${cam[1]}: ${got[axis]} vs ${want[k]}`);
      });
      return got;
    };
    const first = await check(homeCam);

    let before = await frameCount(page);
    await drag(page, 150, 60);
    const turned = await settledPixels(page, { from: before });
    await page.waitForURL((url) => camOf(url)[0] !== homeCam[0]);
    const cam = camOf(page.url());
    t.diagnostic(`yaw ${homeCam[0]} -> ${cam[0]}, pitch ${homeCam[1]} -> ${cam[1]}`);
    const second = await check(cam);
    assert.ok(Math.abs(first.x[0] - second.x[0]) > 0.1, 'the widget turned');
    assert.ok(meanAbsDiff(home, turned) > CHANGED);

    before = await frameCount(page);
    await page.getByRole('button', { name: 'Reset to scene camera' }).click();
    const reset = await settledPixels(page, { from: before });
    await page.waitForURL((url) => camOf(url).every((v, i) => Math.abs(v - homeCam[i]) < 1e-5));
    await check(homeCam);
    assert.ok(meanAbsDiff(home, reset) < SAME, 'the scene camera\'s picture again');
  });
});

test('a named bookmark is kept in the URL, listed, and brings its view back; copy link copies the address', async () => {
  await withPage('bookmarks', async ({ server, page }) => {
    await page.context().grantPermissions(['clipboard-read', 'clipboard-write'], { origin: server.url });
    await page.goto(`${server.url}?scene=blobs&t=3&scale=0.5`);
    await settledPixels(page);
    // A view worth keeping: turned, another isovalue, a colour map.
    let before = await frameCount(page);
    await drag(page, -90, 20);
    await settledPixels(page, { from: before });
    before = await frameCount(page);
    await page.selectOption('#cmap', 'inferno');
    const kept = await settledPixels(page, { from: before });
    await page.waitForURL(/cmap=inferno/);
    const keptCam = camOf(page.url());

    await page.locator('#bm-name').fill('Front, inferno');
    await page.locator('#bm-save').click();
    await page.waitForURL(/bm=Front/);
    assert.deepEqual(await page.locator('#bookmarks .bm-go').allTextContents(), ['Front, inferno']);

    // Elsewhere: another camera, no map.
    before = await frameCount(page);
    await drag(page, 160, -40);
    await page.selectOption('#cmap', '');
    const elsewhere = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(kept, elsewhere) > CHANGED);

    // Copy link: the clipboard holds the page's address, bookmark included.
    await page.locator('#copy-link').click();
    await page.waitForFunction(() => document.getElementById('bm-status').textContent === 'Link copied.');
    const copied = await page.evaluate(() => navigator.clipboard.readText());
    assert.equal(copied, page.url());
    assert.match(copied, /bm=Front/);

    // Going to the bookmark reloads the page with its view.
    await Promise.all([page.waitForEvent('load'), page.locator('#bookmarks .bm-go').click()]);
    const back = await settledPixels(page);
    assert.deepEqual(camOf(page.url()), keptCam);
    assert.match(page.url(), /cmap=inferno/);
    assert.deepEqual(await page.locator('#bookmarks .bm-go').allTextContents(), ['Front, inferno'], 'still listed');
    assert.ok(meanAbsDiff(kept, back) < SAME, 'the bookmarked picture again');

    await page.getByRole('button', { name: 'Delete bookmark Front, inferno' }).click();
    await page.waitForURL((url) => !new URL(url).searchParams.has('bm'));
    assert.equal(await page.locator('#bm-empty').isVisible(), true);
  });
});
