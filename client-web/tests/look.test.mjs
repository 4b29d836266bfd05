// The viewer's own look against the real server: the clip box's handles dragged in the view,
// further isosurfaces added with a colour and removed, and a colour map of the isovalue with
// its legend.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, settledPixels, meanAbsDiff, frameCount } from './harness.mjs';
import { createTetBall } from './scenes.mjs';

const CHANGED = 2; // see viewer.test.mjs
const SAME = 0.5; // see state.test.mjs

/**
 * The pixels once the still frame answering every input sent so far is on screen (a frame
 * header carries the newest input it reflects), then settled.
 */
async function settledAfterInputs(page) {
  const sent = await page.evaluate(() => window.isoray.connection.nextInputId - 1);
  await page.waitForFunction((id) => {
    const h = window.isoray.view.lastHeader;
    return h && h.inputId >= id && (h.flags & 1) === 1;
  }, sent, { timeout: 30000 });
  return settledPixels(page);
}

/** The share of pixels whose colour moves by more than 32 in some channel. */
const changedShare = (a, b) => {
  let changed = 0;
  for (let i = 0; i < a.data.length; i += 4) {
    if ([0, 1, 2].some((c) => Math.abs(a.data[i + c] - b.data[i + c]) > 32)) changed += 1;
  }
  return changed / (a.data.length / 4);
};

/** The clip box in the page's URL, or null. */
const clipOf = (url) => {
  const v = new URL(url).searchParams.get('clip');
  return v ? v.split(',').map(Number) : null;
};

test('dragging a clip-box handle in the view changes the image and the URL', async (t) => {
  await withPage('clip-handles', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3&scale=0.5`);
    const plain = await settledPixels(page);
    // The fields' ranges come from the scene's bounds (GET /api/v1/scenes/{id}).
    await page.waitForFunction(() => window.isoray.look.bounds !== null);
    const bounds = await page.evaluate(() => window.isoray.look.bounds);
    assert.ok(bounds.min.every((v, i) => v < bounds.max[i]), `bounds ${JSON.stringify(bounds)}`);
    assert.ok(Number(await page.locator('#clip-min-x').getAttribute('min')) < bounds.min[0]);

    let before = await frameCount(page);
    await page.locator('#clip-on').check();
    const clipped = await settledPixels(page, { from: before });
    await page.waitForURL(/clip=/);
    const box = clipOf(page.url());
    assert.ok(meanAbsDiff(plain, clipped) > CHANGED, 'switching the clip box on cuts the blobs');
    const fields = () => page.evaluate(() => [...document.querySelectorAll('#panel .clip-grid input')]
      .map((i) => ({ id: i.id, value: i.value, text: i.scrollWidth, room: i.clientWidth })));
    assert.deepEqual((await fields()).map((f) => Number(f.value)), box, 'the fields show the box of the URL');

    // Drag the max-x face's handle to the left, along -x as drawn: the right part of the
    // front half comes back.
    const handle = page.locator('#handle-max-x');
    await handle.waitFor({ state: 'visible' });
    await page.locator('#view').scrollIntoViewIfNeeded();
    const hb = await handle.boundingBox();
    const [x, y] = [hb.x + hb.width / 2, hb.y + hb.height / 2];
    before = await frameCount(page);
    await page.mouse.move(x, y);
    await page.mouse.down();
    await page.mouse.move(x - 150, y, { steps: 10 });
    await page.mouse.up();
    const dragged = await settledPixels(page, { from: before });
    await page.waitForURL((url) => clipOf(url) && clipOf(url)[3] < box[3] - 0.5);
    const moved = clipOf(page.url());
    t.diagnostic(`max x ${box[3]} -> ${moved[3]}`);
    assert.deepEqual([...moved.slice(0, 3), ...moved.slice(4)], [...box.slice(0, 3), ...box.slice(4)], 'only the dragged face moved');
    const diff = meanAbsDiff(clipped, dragged);
    t.diagnostic(`mean abs diff ${diff.toFixed(2)}`);
    assert.ok(diff > CHANGED, `the image changed (mean abs diff ${diff.toFixed(2)})`);
    const extent = Math.max(...bounds.max.map((v, i) => v - bounds.min[i]));
    const shown = Number(await page.locator('#clip-max-x').inputValue());
    assert.ok(Math.abs(shown - moved[3]) <= extent / 1000, `and the numeric field follows (${shown} for ${moved[3]})`);

    // A typed value moves the box too, and a reload keeps it.
    before = await frameCount(page);
    await page.locator('#clip-max-y').fill(String(+(box[4] - 1).toFixed(3)));
    await page.locator('#clip-max-y').press('Enter');
    await settledPixels(page, { from: before });
    await page.waitForURL((url) => clipOf(url)[4] === +(box[4] - 1).toFixed(3));

    // In a desktop window's side panel every field shows its whole number.
    await page.setViewportSize({ width: 1280, height: 720 });
    await page.waitForFunction(() => document.getElementById('panel').getBoundingClientRect().left > 640);
    const shownFields = await fields();
    t.diagnostic(`clip fields ${JSON.stringify(shownFields)}`);
    for (const f of shownFields) assert.ok(f.text <= f.room, `${f.id} shows all of "${f.value}" (${f.text} px of text in ${f.room} px)`);
  });
});

test('a scene\'s own clip box is the clip section\'s: shown, switched off and on, replaced by the viewer\'s', async (t) => {
  await withPage('scene-clip', async ({ server, page }) => {
    // The scene's box as the server states it, read off the wire (not from the app).
    const infos = [];
    page.on('websocket', (ws) => ws.on('framereceived', ({ payload }) => {
      if (typeof payload === 'string' && payload.includes('"type":"info"')) infos.push(JSON.parse(payload));
    }));
    // A desktop window, where the shells fill more of the frame than in the harness's.
    await page.setViewportSize({ width: 1280, height: 720 });
    await page.goto(`${server.url}?scene=shells&t=2&scale=0.5`);
    const cut = await settledAfterInputs(page);
    assert.equal(infos.length, 1);
    const own = infos[0].effects.clip;
    assert.ok(own && infos[0].effects.settings.clip_box, `Shells starts cut by its own box: ${JSON.stringify(infos[0].effects)}`);
    const shown = () => page.evaluate(() => ({
      on: document.getElementById('clip-on').checked,
      fields: [...document.querySelectorAll('#panel .clip-grid input')].map((i) => (i.disabled ? null : Number(i.value))),
    }));
    const near = (a, b) => a.every((v, i) => Math.abs(v - b[i]) <= 0.01);
    let s = await shown();
    assert.ok(s.on && near(s.fields, [...own.min, ...own.max]), `the section shows the scene's box: ${JSON.stringify(s)}`);
    assert.equal(await page.locator('#fx-clip_box').count(), 0, 'no second clip-box switch among the effects');

    // Its faces drawn where they cut the scene (the box reaches ±100, far past it), and the
    // face at y = 0.3 dragged down by its handle; the faces far out keep their values.
    await page.waitForFunction(() => window.isoray.look.bounds !== null);
    const handle = page.locator('#handle-max-y');
    await handle.waitFor({ state: 'visible' });
    const hb = await handle.boundingBox();
    const [hx, hy] = [hb.x + hb.width / 2, hb.y + hb.height / 2];
    await page.mouse.move(hx, hy);
    await page.mouse.down();
    await page.mouse.move(hx, hy + 40, { steps: 8 });
    await page.mouse.up();
    await page.waitForURL((url) => clipOf(url) && clipOf(url)[4] < own.max[1] - 0.05);
    const dragged = clipOf(page.url());
    t.diagnostic(`dragged box ${JSON.stringify(dragged)}`);
    assert.ok(near([...dragged.slice(0, 4), dragged[5]], [...own.min, own.max[0], own.max[2]]), 'only the dragged face moved');
    await settledAfterInputs(page);

    // Off: the cut is gone, the effect noted in the URL.
    await page.locator('#clip-on').uncheck();
    const whole = await settledAfterInputs(page);
    // The cut is a small part of the frame: count the pixels it changes.
    t.diagnostic(`cut vs whole: ${(100 * changedShare(cut, whole)).toFixed(1)}% of ${cut.width}×${cut.height} pixels changed`);
    assert.ok(changedShare(cut, whole) > 0.01, 'switching the box off shows the whole shells');
    s = await shown();
    assert.ok(!s.on && s.fields.every((v) => v === null), `off: ${JSON.stringify(s)}`);
    assert.match(page.url(), /fx=[^&]*-clip_box/);

    // On again: the scene's own box, not one of the viewer's.
    await page.locator('#clip-on').check();
    const again = await settledAfterInputs(page);
    t.diagnostic(`cut vs cut again: mean difference ${meanAbsDiff(cut, again).toFixed(2)}`);
    assert.ok(meanAbsDiff(cut, again) < SAME, 'the scene\'s box cuts as before');
    s = await shown();
    assert.ok(s.on && near(s.fields, [...own.min, ...own.max]), `on again: ${JSON.stringify(s)}`);
    assert.equal(clipOf(page.url()), null, 'no viewer box in the URL');

    // A typed face makes the box the viewer's; off and on again gives the scene's back.
    const top = +(own.max[1] - 0.5).toFixed(3);
    const typeTop = async () => {
      await page.locator('#clip-max-y').fill(String(top));
      await page.locator('#clip-max-y').press('Enter');
      await page.waitForURL((url) => clipOf(url) && clipOf(url)[4] === top);
      return settledAfterInputs(page);
    };
    const lower = await typeTop();
    assert.ok(changedShare(cut, lower) > 0.001, 'the lower face cuts more');
    await page.locator('#clip-on').uncheck();
    await settledAfterInputs(page);
    await page.locator('#clip-on').check();
    const back = await settledAfterInputs(page);
    assert.ok(meanAbsDiff(cut, back) < SAME, 'switched on again, the scene\'s own box cuts');
    s = await shown();
    assert.ok(s.on && near(s.fields, [...own.min, ...own.max]) && clipOf(page.url()) === null, `on again: ${JSON.stringify(s)}`);

    // The viewer's box survives a reload.
    await typeTop();
    await page.reload();
    await settledAfterInputs(page);
    s = await shown();
    assert.ok(s.on && s.fields[4] === top && near(s.fields, [...own.min, own.max[0], top, own.max[2]]), `after a reload: ${JSON.stringify(s)}`);
  });
});

test('adding a second isosurface shows it, and removing it restores the image', async (t) => {
  await withPage('add-surface', async ({ server, page }) => {
    // Spheres of 3 - |p|²: the added surface (a lower value) is a larger sphere around the first.
    const id = await createTetBall(server);
    await page.goto(`${server.url}?scene=${id}&t=0&scale=0.5`);
    const one = await settledPixels(page);
    let before = await frameCount(page);
    await page.locator('#surface-add').click();
    const two = await settledPixels(page, { from: before });
    await page.waitForURL(/surf=/);
    const diff = meanAbsDiff(one, two);
    t.diagnostic(`with a second isosurface: mean abs diff ${diff.toFixed(2)}`);
    assert.ok(diff > CHANGED, `the added isosurface shows (mean abs diff ${diff.toFixed(2)})`);

    // Its colour: a pure green surface makes the picture greener.
    const green = (img) => { let g = 0; for (let i = 0; i < img.data.length; i += 4) g += img.data[i + 1] - (img.data[i] + img.data[i + 2]) / 2; return g / (img.data.length / 4); };
    before = await frameCount(page);
    await page.locator('#further-0 input[type=color]').fill('#00ff00');
    const greener = await settledPixels(page, { from: before });
    assert.ok(green(greener) > green(two) + 1, `the colour applies (${green(two).toFixed(2)} -> ${green(greener).toFixed(2)})`);
    await page.waitForURL(/surf=[^&]*00ff00/);

    before = await frameCount(page);
    await page.locator('#further-0 button.remove').click();
    const removed = await settledPixels(page, { from: before });
    const back = meanAbsDiff(one, removed);
    assert.ok(back < SAME, `removing it restores the image (mean abs diff ${back.toFixed(3)})`);
    await page.waitForURL((url) => !new URL(url).searchParams.has('surf'));
  });
});

test('a colour map recolours the tet surfaces and its legend shows the range', async () => {
  await withPage('color-map', async ({ server, page }) => {
    const id = await createTetBall(server);
    await page.goto(`${server.url}?scene=${id}&t=0&scale=0.5`);
    const own = await settledPixels(page);
    assert.equal(await page.locator('#legend').isHidden(), true, 'no legend without a map');
    const slider = await page.evaluate(() => window.isoray.look.info.isovalue_slider);

    // Grey: every lit surface pixel is grey; the scene's own colours were not.
    const coloured = (img) => { let n = 0; for (let i = 0; i < img.data.length; i += 4) { const d = img.data; if (Math.max(d[i], d[i + 1], d[i + 2]) - Math.min(d[i], d[i + 1], d[i + 2]) > 40) n += 1; } return n / (img.data.length / 4); };
    let before = await frameCount(page);
    await page.selectOption('#cmap', 'grey');
    const grey = await settledPixels(page, { from: before });
    assert.ok(coloured(own) > 0.05, `the scene's own map colours the surface (${coloured(own).toFixed(3)})`);
    assert.ok(coloured(grey) < 0.005, `the grey map leaves no coloured pixel (${coloured(grey).toFixed(4)})`);
    await page.waitForURL(/cmap=grey/);
    const legend = page.locator('#legend');
    assert.equal(await legend.isVisible(), true, 'the legend shows');
    assert.equal(Number(await page.locator('#legend-lo').textContent()), +slider[0].toPrecision(5));
    assert.equal(Number(await page.locator('#legend-hi').textContent()), +slider[1].toPrecision(5));

    // Viridis over a chosen range: other colours, and the legend says the range.
    before = await frameCount(page);
    await page.selectOption('#cmap', 'viridis');
    const viridis = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(grey, viridis) > CHANGED, 'another map, other colours');
    before = await frameCount(page);
    // The isovalue (2.5, the top of the slider's range) moves to the map's low end.
    await page.locator('#cmap-hi').fill('5');
    await page.locator('#cmap-hi').press('Enter');
    await page.locator('#cmap-lo').fill('2.45');
    await page.locator('#cmap-lo').press('Enter');
    await page.waitForURL(/cmap=viridis%2C2\.45%2C5(&|$)/);
    const ranged = await settledAfterInputs(page);
    const rangeDiff = meanAbsDiff(viridis, ranged);
    assert.ok(rangeDiff > CHANGED, `another range, other colours (mean abs diff ${rangeDiff.toFixed(2)})`);
    assert.equal(await page.locator('#legend-lo').textContent(), '2.45');
    assert.equal(await page.locator('#legend-hi').textContent(), '5');
    assert.match(await legend.getAttribute('aria-label'), /Viridis from 2\.45 to 5$/);
    assert.match(await page.locator('#legend-bar').evaluate((e) => e.style.background), /rgb\(68, 1, 84\).*rgb\(253, 231, 37\)/);

    before = await frameCount(page);
    await page.selectOption('#cmap', '');
    const back = await settledPixels(page, { from: before });
    assert.ok(meanAbsDiff(own, back) < SAME, 'no map: the scene\'s own colours again');
  });
});

test('a scene\'s own further isosurfaces are the section\'s: listed, switched off and on, edited, and back', async (t) => {
  await withPage('scene-surfaces', async ({ server, page }) => {
    // The scene's surfaces as the server states them, read off the wire (not from the app).
    const infos = [];
    page.on('websocket', (ws) => ws.on('framereceived', ({ payload }) => {
      if (typeof payload === 'string' && payload.includes('"type":"info"')) infos.push(JSON.parse(payload));
    }));
    await page.goto(`${server.url}?scene=shells&t=2&scale=0.5`);
    const own = await settledAfterInputs(page);
    const listed = infos[0].effects.surfaces;
    assert.ok(listed && listed.length === 2 && infos[0].effects.settings.isosurfaces, `Shells has two of its own, on: ${JSON.stringify(infos[0].effects)}`);
    const rows = () => page.evaluate(() => [...document.querySelectorAll('#further fieldset')].map((f) => ({
      legend: f.querySelector('legend').textContent,
      value: Number(f.querySelector('input[type=number]').value),
      disabled: f.disabled,
    })));
    const surfParam = () => new URL(page.url()).searchParams.get('surf');
    const fxParam = () => new URL(page.url()).searchParams.get('fx') ?? '';
    let r = await rows();
    assert.deepEqual(r.map((x) => x.legend), ['Scene isosurface 1', 'Scene isosurface 2']);
    assert.deepEqual(r.map((x) => x.value), listed.map((s) => s.isovalue), 'the rows show the scene\'s isovalues');
    assert.ok(await page.locator('#surfaces-on').isChecked(), 'switched on, as the scene starts');
    assert.equal(await page.locator('#fx-isosurfaces').count(), 0, 'no second switch among the effects');

    // Off: the shells are gone, the rows greyed, the effect noted in the URL; on: as before.
    await page.locator('#surfaces-on').uncheck();
    const off = await settledAfterInputs(page);
    t.diagnostic(`own vs off: ${(100 * changedShare(own, off)).toFixed(1)}% of the pixels changed`);
    assert.ok(changedShare(own, off) > 0.01, 'switching off hides the scene\'s further isosurfaces');
    assert.ok((await rows()).every((x) => x.disabled), 'the rows are greyed while off');
    assert.match(fxParam(), /-isosurfaces/);
    await page.locator('#surfaces-on').check();
    const on = await settledAfterInputs(page);
    assert.ok(meanAbsDiff(own, on) < SAME, 'on again, the scene\'s own');
    assert.doesNotMatch(fxParam(), /isosurfaces/);

    // Editing the core's isovalue makes the list the viewer's, both surfaces kept.
    await page.locator('#further-1 input[type=number]').fill('1.5');
    await page.locator('#further-1 input[type=number]').press('Enter');
    await page.waitForURL(() => (surfParam() ?? '').split(',').length === 2);
    const edited = await settledAfterInputs(page);
    assert.ok(changedShare(own, edited) > 0.001, 'a larger core shows');
    r = await rows();
    assert.deepEqual(r.map((x) => [x.legend, x.value]), [['Further isosurface 1', listed[0].isovalue], ['Further isosurface 2', 1.5]]);
    // Each adopted surface keeps its scene surface's material (`:k` in the URL): the core back
    // at its own isovalue looks as the scene drew it, the translucent shell tinted by the
    // balls' colours as before, not redrawn plain.
    assert.match(surfParam(), /^[^,]*:0,[^,]*:1$/, 'both rows drawn like the scene\'s');
    await page.locator('#further-1 input[type=number]').fill(String(listed[1].isovalue));
    await page.locator('#further-1 input[type=number]').press('Enter');
    await page.waitForURL(() => !(surfParam() ?? '1.5:').includes('1.5:'));
    const restored = await settledAfterInputs(page);
    t.diagnostic(`own vs restored: mean abs diff ${meanAbsDiff(own, restored).toFixed(3)}`);
    assert.ok(meanAbsDiff(own, restored) < SAME, 'the core back at its isovalue: the scene\'s look');
    // Added: three, the scene's two among them.
    await page.locator('#surface-add').click();
    await page.waitForURL(() => (surfParam() ?? '').split(',').length === 3);

    // Off and on again: the scene's own, not the viewer's.
    await page.locator('#surfaces-on').uncheck();
    await page.locator('#surfaces-on').check();
    const back = await settledAfterInputs(page);
    assert.ok(meanAbsDiff(own, back) < SAME, 'off and on again gives the scene\'s own back');
    assert.equal(surfParam(), null, 'no viewer surfaces in the URL');
    assert.deepEqual((await rows()).map((x) => x.legend), ['Scene isosurface 1', 'Scene isosurface 2']);

    // Removing both: the scene's own again, switched off.
    await page.locator('#further-0 button.remove').click();
    await page.waitForURL(() => (surfParam() ?? '').split(',').length === 1);
    assert.deepEqual((await rows()).map((x) => x.value), [listed[1].isovalue], 'the core is left');
    await page.locator('#further-0 button.remove').click();
    await page.waitForURL(() => surfParam() === null && /-isosurfaces/.test(fxParam()));
    const none = await settledAfterInputs(page);
    assert.ok(meanAbsDiff(off, none) < SAME, 'nothing further is drawn');
    assert.ok(!(await page.locator('#surfaces-on').isChecked()));
    assert.ok((await rows()).every((x) => x.disabled));
  });
});

test('a scene drawn as a volume greys its isosurface controls while transparency is on', async () => {
  await withPage('volume-note', async ({ page, server }) => {
    const infos = [];
    page.on('websocket', (ws) => ws.on('framereceived', ({ payload }) => {
      if (typeof payload === 'string' && payload.includes('"type":"info"')) infos.push(JSON.parse(payload));
    }));
    await page.goto(`${server.url}?scene=clouds&t=2&scale=0.5`);
    await settledAfterInputs(page);
    assert.ok(infos[0].effects.volume && infos[0].effects.settings.transparency, `Clouds starts as a volume: ${JSON.stringify(infos[0].effects)}`);
    const idle = (sel) => page.locator(sel).evaluate((e) => e.closest('[inert]') !== null);
    const note = page.locator('#volume-note');
    assert.ok(await note.isVisible(), 'the note says why the controls are greyed');
    for (const sel of ['#isovalue', '#surface-add', '#cmap']) assert.ok(await idle(sel), `${sel} takes no input as a volume`);

    // Transparency off: a surface, and every control works again.
    await page.locator('#fx-transparency').uncheck();
    await note.waitFor({ state: 'hidden' });
    for (const sel of ['#isovalue', '#surface-add', '#cmap']) assert.ok(!(await idle(sel)), `${sel} works on the surface`);

    // A see-through further isosurface turns transparency on, and the panel shows it.
    await page.locator('#surface-add').click();
    await page.locator('#further-opacity-0').fill('0.5');
    await page.locator('#further-opacity-0').dispatchEvent('change');
    await note.waitFor({ state: 'visible' });
    assert.ok(await page.locator('#fx-transparency').isChecked(), 'the transparency switch follows');
    // Back to the scene's start, so the URL no longer notes it off.
    await page.waitForURL((url) => !/-transparency/.test(url.searchParams.get('fx') ?? ''));
  });
});

test('a scene with no volume keeps its isosurface controls with transparency on', async () => {
  await withPage('no-volume-note', async ({ page, server }) => {
    await page.goto(`${server.url}?scene=shells&t=2&scale=0.5`);
    await settledAfterInputs(page);
    assert.ok(await page.locator('#fx-transparency').isChecked(), 'Shells starts see-through');
    assert.ok(await page.locator('#volume-note').isHidden());
    assert.ok(await page.locator('#isovalue').evaluate((e) => e.closest('[inert]') === null));
  });
});
