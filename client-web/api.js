// The server's HTTP API and stream addresses, with the view token when the page has one
// (`?token=…`, for servers started with `--view-token`): REST calls send it as a bearer
// token, the websocket (which cannot send headers from a browser) as `?token=`.

const token = new URLSearchParams(location.search).get('token');

/** The page's view token, or null. */
export function viewToken() {
  return token;
}

/** `fetch` of an API path, authorised with the view token. */
export function apiFetch(path) {
  return fetch(path, token ? { headers: { authorization: `Bearer ${token}` } } : undefined);
}

/** Why a response failed, in words a viewer can act on. */
export function describeFailure(response) {
  if (response.status === 401 || response.status === 403) {
    return token
      ? `the server refused the view token (HTTP ${response.status})`
      : `the server needs a view token: open this page with ?token=… (HTTP ${response.status})`;
  }
  return `HTTP ${response.status}`;
}

/** The websocket address of a scene's stream. */
export function streamUrl(scene) {
  const proto = location.protocol === 'https:' ? 'wss' : 'ws';
  const query = token ? `?token=${encodeURIComponent(token)}` : '';
  return `${proto}://${location.host}/api/v1/scenes/${encodeURIComponent(scene)}/stream${query}`;
}
