// The viewer's settings and their place in the URL: everything a user chooses (scene, camera,
// view-up axis, isovalues, time, playback, effects, quality, overlay) is kept in the query
// string, so a view can be shared and reloaded. Only values that differ from the defaults are
// written; values that do not parse are ignored (the default stays), never thrown.

export const UP_AXES = ['+y', '+z', '+x', '-y', '-z', '-x'];

/** Defaults of every setting. `cam` and `iso` come from the server's `info` when null. */
export function defaults() {
  return {
    scene: null,
    cam: null, // { yaw, pitch, distance, target: [x, y, z], fov }
    up: '+y',
    iso: null, // [value]: the main isosurface's isovalue
    time: null, // pinned scene time in seconds; null follows the live state
    speed: 1, // playback speed: scene seconds per second (demos) or steps per second (stored)
    loop: true,
    fx: {}, // effect -> on (boolean) or quality setting -> level (number), where the user differs from the scene
    codec: 'auto', // preferred codec while the view moves (`auto`: the browser's order)
    scale: 1, // resolution scale on top of canvas size × devicePixelRatio
    fps: null, // target frame rate, null for the server's default
    stats: false,
    token: null, // view token (servers with --view-token); kept so a reload still works
    clip: null, // the viewer's clip box [minx, miny, minz, maxx, maxy, maxz], on while set
    surf: [], // added isosurfaces: { v: isovalue, c: 'rrggbb' (sRGB), o: opacity, k: the scene surface it is drawn like (optional) }
    cmap: null, // colour map of the isovalue: { name, lo, hi }
    bm: [], // bookmarks: { name, q } where q is the query string of the view they keep
    extra: [], // query parameters this module does not know (other modules' switches), kept as they are
  };
}

const KNOWN = ['scene', 'cam', 'up', 'iso', 't', 'speed', 'loop', 'fx', 'codec', 'scale', 'fps', 'stats', 'token',
  'clip', 'surf', 'cmap', 'bm'];
export const COLOR_MAPS = ['viridis', 'inferno', 'cool_warm', 'grey'];
/** The settings a bookmark keeps (camera, isovalues, time, effects and the viewer's look). */
export const BOOKMARKED = ['cam', 'up', 'iso', 't', 'fx', 'clip', 'surf', 'cmap'];

const finite = (s) => (s !== null && s.trim() !== '' && Number.isFinite(Number(s)) ? Number(s) : null);

/** Settings read from a query string; unknown or malformed values fall back to defaults. */
export function parseSettings(search) {
  const p = new URLSearchParams(search);
  const s = defaults();
  if (p.get('scene')) s.scene = p.get('scene');
  const cam = (p.get('cam') || '').split(',').map(finite);
  if (cam.length === 7 && cam.every((v) => v !== null) && cam[2] > 0 && cam[6] >= 1 && cam[6] <= 170) {
    s.cam = { yaw: cam[0], pitch: cam[1], distance: cam[2], target: cam.slice(3, 6), fov: cam[6] };
  }
  if (UP_AXES.includes(p.get('up'))) s.up = p.get('up');
  const iso = (p.get('iso') || '').split(',').map(finite);
  if (p.get('iso') && iso.every((v) => v !== null)) s.iso = iso;
  const t = finite(p.get('t'));
  if (t !== null && t >= 0) s.time = t;
  const speed = finite(p.get('speed'));
  if (speed !== null && speed > 0 && speed <= 100) s.speed = speed;
  if (p.get('loop') === '0') s.loop = false;
  for (const item of (p.get('fx') || '').split(',').filter(Boolean)) {
    const toggle = /^(-?)([a-z_]+)$/.exec(item);
    const level = /^([a-z_]+):(\d{1,4})$/.exec(item);
    if (toggle) s.fx[toggle[2]] = toggle[1] !== '-';
    else if (level) s.fx[level[1]] = Number(level[2]);
  }
  if (/^[a-z0-9]{1,16}$/.test(p.get('codec') || '')) s.codec = p.get('codec');
  const scale = finite(p.get('scale'));
  if (scale !== null && scale >= 0.1 && scale <= 2) s.scale = scale;
  const fps = finite(p.get('fps'));
  if (fps !== null && fps >= 1 && fps <= 240) s.fps = fps;
  if (p.get('stats') === '1') s.stats = true;
  if (p.get('token')) s.token = p.get('token');
  const clip = (p.get('clip') || '').split(',').map(finite);
  if (clip.length === 6 && clip.every((v) => v !== null) && [0, 1, 2].every((i) => clip[i] < clip[i + 3])) s.clip = clip;
  for (const item of (p.get('surf') || '').split(',').filter(Boolean).slice(0, 4)) {
    // `v:c:o`, or `v:c:o:k` for one drawn like the scene's own surface k.
    const m = /^(-?[0-9.e+-]+):([0-9a-f]{6}):([0-9.]+)(?::([0-9]))?$/.exec(item);
    if (m && finite(m[1]) !== null && Number(m[3]) >= 0 && Number(m[3]) <= 1) {
      const row = { v: Number(m[1]), c: m[2], o: Number(m[3]) };
      if (m[4] !== undefined) row.k = Number(m[4]);
      s.surf.push(row);
    }
  }
  const cmap = (p.get('cmap') || '').split(',');
  if (cmap.length === 3 && COLOR_MAPS.includes(cmap[0]) && finite(cmap[1]) !== null && finite(cmap[2]) !== null && Number(cmap[1]) < Number(cmap[2])) {
    s.cmap = { name: cmap[0], lo: Number(cmap[1]), hi: Number(cmap[2]) };
  }
  for (const item of p.getAll('bm')) {
    const at = item.indexOf(':');
    const name = item.slice(0, at);
    if (at > 0 && name.length <= 60) s.bm.push({ name, q: item.slice(at + 1) });
  }
  s.extra = [...p].filter(([k]) => !KNOWN.includes(k));
  return s;
}

const round = (v) => String(+v.toFixed(6));

/** The part of `s`'s query string a bookmark keeps (no `?`). */
export function bookmarkQuery(s) {
  const all = new URLSearchParams(serializeSettings({ ...s, bm: [], extra: [] }).replace(/^[^?]*\?/, ''));
  const kept = new URLSearchParams();
  for (const [k, v] of all) if (BOOKMARKED.includes(k)) kept.append(k, v);
  return kept.toString();
}

/** `s` with the view of bookmark query `q`: bookmarked settings replaced, the rest kept. */
export function withBookmark(s, q) {
  const from = parseSettings(q);
  const out = { ...s };
  for (const key of ['cam', 'up', 'iso', 'time', 'fx', 'clip', 'surf', 'cmap']) out[key] = from[key];
  return out;
}

/** The query string (with `?`) that `parseSettings` reads back as `s`. */
export function serializeSettings(s) {
  const d = defaults();
  const p = new URLSearchParams();
  if (s.scene) p.set('scene', s.scene);
  if (s.cam) {
    const c = s.cam;
    p.set('cam', [c.yaw, c.pitch, c.distance, ...c.target, c.fov].map(round).join(','));
  }
  if (s.up !== d.up) p.set('up', s.up);
  if (s.iso) p.set('iso', s.iso.map(round).join(','));
  if (s.time !== null) p.set('t', round(s.time));
  if (s.speed !== d.speed) p.set('speed', round(s.speed));
  if (!s.loop) p.set('loop', '0');
  const fx = Object.entries(s.fx).map(([k, v]) => (typeof v === 'number' ? `${k}:${v}` : v ? k : `-${k}`));
  if (fx.length) p.set('fx', fx.join(','));
  if (s.codec !== d.codec) p.set('codec', s.codec);
  if (s.scale !== d.scale) p.set('scale', round(s.scale));
  if (s.fps !== null) p.set('fps', round(s.fps));
  if (s.stats) p.set('stats', '1');
  if (s.token) p.set('token', s.token);
  if (s.clip) p.set('clip', s.clip.map(round).join(','));
  if (s.surf.length) p.set('surf', s.surf.map((x) => `${round(x.v)}:${x.c}:${round(x.o)}${x.k === undefined ? '' : `:${x.k}`}`).join(','));
  if (s.cmap) p.set('cmap', `${s.cmap.name},${round(s.cmap.lo)},${round(s.cmap.hi)}`);
  for (const b of s.bm) p.append('bm', `${b.name}:${b.q}`);
  for (const [k, v] of s.extra) p.append(k, v);
  const text = p.toString();
  return text ? `?${text}` : location.pathname;
}
