// Views that survive: named bookmarks of the camera, isovalues, time, effects and the
// viewer's look, kept in the URL (`bm=name:query`, so a shared link carries them) and listed
// on the page; going to one reloads the page with its view, which the viewer restores as it
// restores any URL. The "copy link" button puts the page's address on the clipboard.
import { $ } from './ui.js';
import { bookmarkQuery } from './settings.js';

const MAX_BOOKMARKS = 20;

export class Bookmarks {
  /** `flush()` writes the URL now; `go(q)` shows the view of bookmark query `q`. */
  constructor(settings, { flush, go }) {
    this.settings = settings;
    this.flush = flush;
    this.go = go;
    this.list = $('bookmarks');
    this.name = $('bm-name');
    $('bm-form').addEventListener('submit', (e) => {
      e.preventDefault();
      this.save(this.name.value.trim() || `View ${this.settings.bm.length + 1}`);
      this.name.value = '';
    });
    $('copy-link').addEventListener('click', () => this.copyLink());
    this.#render();
  }

  /** Keeps the current view under `name` (replacing a bookmark of that name). */
  save(name) {
    const clean = name.replace(/[^\p{L}\p{N} _.,()-]/gu, '').slice(0, 60) || 'View';
    const q = bookmarkQuery(this.settings);
    const at = this.settings.bm.findIndex((b) => b.name === clean);
    if (at >= 0) this.settings.bm[at] = { name: clean, q };
    else this.settings.bm.push({ name: clean, q });
    this.settings.bm = this.settings.bm.slice(-MAX_BOOKMARKS);
    this.flush();
    this.#render();
    $('bm-status').textContent = `Saved “${clean}”.`;
  }

  async copyLink() {
    this.flush();
    const status = $('bm-status');
    try {
      await navigator.clipboard.writeText(location.href);
      status.textContent = 'Link copied.';
    } catch {
      // No clipboard (permissions, insecure origin): show the link to copy by hand.
      const field = $('link-text');
      field.hidden = false;
      field.value = location.href;
      field.select();
      status.textContent = 'Copy the selected link.';
    }
  }

  #render() {
    this.list.replaceChildren(...this.settings.bm.map((b, i) => {
      const item = document.createElement('li');
      const go = document.createElement('button');
      go.type = 'button';
      go.className = 'bm-go';
      go.textContent = b.name;
      go.title = `Go to the view “${b.name}”`;
      go.addEventListener('click', () => this.go(b.q));
      const remove = document.createElement('button');
      remove.type = 'button';
      remove.className = 'bm-remove';
      remove.textContent = '×';
      remove.setAttribute('aria-label', `Delete bookmark ${b.name}`);
      remove.addEventListener('click', () => {
        this.settings.bm.splice(i, 1);
        this.flush();
        this.#render();
      });
      item.append(go, remove);
      return item;
    }));
    $('bm-empty').hidden = this.settings.bm.length > 0;
  }
}
