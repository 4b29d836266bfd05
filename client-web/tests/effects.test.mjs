// Effect toggles come from the server's list of what a scene can use: switching one changes
// the picture, and a scene without reflective materials offers no reflection toggle while
// one with a mirror-like material does.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, settledPixels, meanAbsDiff, frameCount, api } from './harness.mjs';

const CHANGED = 2; // see viewer.test.mjs
const SAME = 0.5; // see state.test.mjs
// Shadows the blobs cast on each other cover a small share of the frame: measured 1.5 mean
// abs diff at this view. The same view re-rendered differs by 0 (lossless, deterministic).
const SHADOWS_CHANGED = 0.5;

test('a demo offers only the effects it can use; toggling shadows changes the picture and survives a reload', async (t) => {
  await withPage('effects-demo', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3`);
    const plain = await settledPixels(page);
    const available = await page.evaluate(() => window.isoray.effects.info.available);
    const toggles = await page.locator('#effects input[type=checkbox]').evaluateAll((els) => els.map((e) => e.id));
    assert.deepEqual(toggles, available.map((name) => `fx-${name}`), 'one toggle per effect the server lists, no more');
    assert.ok(available.includes('shadows'), `the blobs have a light, so shadows (${available})`);
    assert.ok(!available.includes('reflections'), 'no reflective material in the blobs');
    assert.equal(await page.locator('#fx-reflections').count(), 0, 'so no reflection toggle');
    assert.equal(await page.locator('#fx-depth').count(), 0, 'nor a bounce setting');

    let before = await frameCount(page);
    await page.locator('#fx-shadows').check();
    const shadowed = await settledPixels(page, { from: before });
    const diff = meanAbsDiff(plain, shadowed);
    t.diagnostic(`shadows on vs off: mean abs diff ${diff.toFixed(3)}`);
    assert.ok(diff > SHADOWS_CHANGED, `shadows change the picture (mean abs diff ${diff.toFixed(3)})`);
    await page.waitForURL(/fx=shadows/);

    await page.reload();
    const reloaded = await settledPixels(page);
    assert.equal(await page.locator('#fx-shadows').isChecked(), true, 'the toggle is restored from the URL');
    assert.ok(meanAbsDiff(shadowed, reloaded) < SAME, 'and so is the picture');

    before = await frameCount(page);
    await page.locator('#fx-shadows').uncheck();
    const off = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(plain, off) < SAME, 'switching shadows off again gives the plain picture');
  });
});

test('a scene with a mirror-like material offers reflections, and they change the picture', async (t) => {
  await withPage('effects-reflective', async ({ server, page }) => {
    const created = await api(server, 'POST', '/api/v1/scenes', {
      kind: 'metaballs',
      name: 'Mirror blobs',
      camera: { eye: [0, 2.5, 6], target: [0, -0.3, 0] },
      lighting: {
        materials: [{ diffuse: [0.9, 0.9, 0.9], reflectivity: 0.7 }],
        floor: { height: -1.2, checker: 0.5 },
      },
    });
    const { id } = created.scene;
    const positions = [[-1, 0, 0], [1, 0, 0], [0, 0.3, 1], [0, -0.2, -1]];
    await api(server, 'PUT', `/api/v1/scenes/${id}/steps/0`, { positions, radii: positions.map(() => 1.0) }, created.write_token);

    await page.goto(`${server.url}?scene=${id}&t=0`);
    const plain = await settledPixels(page);
    assert.equal(await page.locator('#fx-reflections').count(), 1, 'a reflection toggle');
    assert.equal(await page.locator('#fx-depth').count(), 1, 'with its bounce setting');

    const before = await frameCount(page);
    await page.locator('#fx-reflections').check();
    const mirrored = await settledPixels(page, { from: before });
    const diff = meanAbsDiff(plain, mirrored);
    t.diagnostic(`reflections on vs off: mean abs diff ${diff.toFixed(3)}`);
    assert.ok(diff > CHANGED, `reflections change the picture (mean abs diff ${diff.toFixed(2)})`);
  });
});
