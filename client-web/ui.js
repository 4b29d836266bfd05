// Small DOM helpers shared by the viewer's modules: the status banner (connecting, waiting for
// the first frame, reconnecting) and dismissible error messages.

export const $ = (id) => document.getElementById(id);

/** Shows `text` in the status banner over the view (with a spinner), or hides it for ''. */
export function setStatus(text, { busy = true } = {}) {
  const el = $('status');
  $('status-text').textContent = text || '';
  el.hidden = !text;
  el.classList.toggle('busy', Boolean(text) && busy);
  el.dataset.state = text ? 'shown' : 'hidden';
}

const MAX_ERRORS = 4;

/**
 * Shows an error that stays until dismissed (its × button, or Escape while it has focus).
 * The same text twice in a row bumps a counter instead of stacking copies.
 */
export function showError(text) {
  const list = $('errors');
  const last = list.lastElementChild;
  if (last && last.dataset.text === text) {
    const n = Number(last.dataset.count) + 1;
    last.dataset.count = String(n);
    last.querySelector('.count').textContent = `×${n}`;
    return;
  }
  const item = document.createElement('div');
  item.className = 'error';
  item.dataset.text = text;
  item.dataset.count = '1';
  const message = document.createElement('span');
  message.textContent = text;
  const count = document.createElement('span');
  count.className = 'count';
  const close = document.createElement('button');
  close.type = 'button';
  close.className = 'dismiss';
  close.textContent = '×';
  close.setAttribute('aria-label', `Dismiss: ${text}`);
  close.addEventListener('click', () => item.remove());
  item.addEventListener('keydown', (e) => { if (e.key === 'Escape') item.remove(); });
  item.append(message, count, close);
  list.append(item);
  while (list.children.length > MAX_ERRORS) list.firstElementChild.remove();
}

/** Fills a `<select>` with `[value, label]` pairs, keeping `selected` if present. */
export function fillSelect(select, options, selected) {
  select.replaceChildren(...options.map(([value, label]) => new Option(label, value)));
  if (options.some(([value]) => value === selected)) select.value = selected;
}
