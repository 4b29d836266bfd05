import { streamUrl } from './api.js';

// The websocket to one scene: numbered inputs, frames handed over in order and acknowledged
// once shown, and automatic reconnection with exponential back-off (and a little jitter, so a
// restarted server is not hit by every viewer at the same instant).

const FIRST_DELAY_MS = 250;
const MAX_DELAY_MS = 5000;

export class Connection {
  /**
   * handlers: `info(message)`, `frame(buffer) -> Promise` (resolves once the frame is shown),
   * `serverError(message)`, `state(name, detail)` with name `connecting`, `open`, or
   * `waiting` (detail: `{ delayMs, attempt, reason }`) before the next attempt.
   */
  constructor(handlers) {
    this.handlers = handlers;
    this.socket = null;
    this.scene = null;
    this.nextInputId = 1;
    this.sentAt = new Map(); // input_id -> performance.now() when sent
    this.delayMs = FIRST_DELAY_MS;
    this.attempt = 0;
    this.timer = null;
    this.frames = Promise.resolve();
  }

  /** Connects to `scene`, closing any previous socket. */
  open(scene) {
    this.scene = scene;
    this.delayMs = FIRST_DELAY_MS;
    this.attempt = 0;
    this.#drop();
    this.#connect();
  }

  get isOpen() {
    return this.socket !== null && this.socket.readyState === WebSocket.OPEN;
  }

  /** Sends an input with a fresh `input_id`; returns the id, or null when not connected. */
  send(message) {
    if (!this.isOpen) return null;
    const inputId = this.nextInputId++;
    this.sentAt.set(inputId, performance.now());
    this.socket.send(JSON.stringify({ ...message, input_id: inputId }));
    return inputId;
  }

  /**
   * Milliseconds from sending input `inputId` to now, the first time a frame reflects it
   * (null afterwards, and for frames that answer no new input). Forgets older inputs too.
   */
  latencyOf(inputId) {
    const sent = this.sentAt.get(inputId);
    for (const id of this.sentAt.keys()) if (id <= inputId) this.sentAt.delete(id);
    return sent === undefined ? null : performance.now() - sent;
  }

  #drop() {
    clearTimeout(this.timer);
    const old = this.socket;
    this.socket = null;
    if (old) old.close(1000, 'viewer changed scene');
  }

  #connect() {
    const socket = new WebSocket(streamUrl(this.scene));
    socket.binaryType = 'arraybuffer';
    this.socket = socket;
    this.sentAt.clear();
    this.frames = Promise.resolve();
    this.attempt += 1;
    this.handlers.state('connecting', { attempt: this.attempt });
    socket.addEventListener('open', () => {
      if (this.socket === socket) this.handlers.state('open', {});
    });
    socket.addEventListener('message', (event) => {
      if (this.socket !== socket) return;
      if (typeof event.data === 'string') {
        let message;
        try {
          message = JSON.parse(event.data);
        } catch (err) {
          this.handlers.serverError({ code: 'bad_message', message: `the server sent text that is not JSON: ${err.message}` });
          return;
        }
        if (message.type === 'info') {
          // A session that reached `info` is healthy: the next loss starts the back-off anew.
          this.delayMs = FIRST_DELAY_MS;
          this.attempt = 0;
          this.handlers.info(message);
        } else if (message.type === 'error') {
          this.handlers.serverError(message);
        } else if (this.handlers.message) {
          this.handlers.message(message);
        }
        return;
      }
      // Frames are shown one after another, in order, and each is acknowledged once shown:
      // the server sends only a small window of frames ahead of the acknowledgements.
      const buffer = event.data;
      this.frames = this.frames.then(async () => {
        if (this.socket !== socket) return;
        let sequence = null;
        try {
          sequence = await this.handlers.frame(buffer);
        } catch (err) {
          this.handlers.serverError({ code: 'bad_frame', message: `a frame could not be shown: ${err.message}` });
        }
        if (sequence !== null && socket.readyState === WebSocket.OPEN) {
          socket.send(JSON.stringify({ type: 'ack', sequence }));
        }
      });
    });
    socket.addEventListener('close', (event) => {
      if (this.socket !== socket) return;
      this.socket = null;
      const jitter = 0.8 + 0.4 * Math.random();
      const delayMs = Math.round(this.delayMs * jitter);
      this.delayMs = Math.min(MAX_DELAY_MS, this.delayMs * 2);
      const reason = event.reason || (event.wasClean ? '' : 'connection lost');
      this.handlers.state('waiting', { delayMs, attempt: this.attempt, reason, code: event.code });
      this.timer = setTimeout(() => this.#connect(), delayMs);
    });
  }
}
