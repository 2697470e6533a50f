// The /ws snapshot stream: keeps only the latest frame's text (parsed lazily, once per animation
// frame), reconnects with backoff, and reports the connection state.

export class Stream {
  /** @param {(connected: boolean) => void} onState */
  constructor(onState) {
    this.onState = onState;
    this.latestText = null;
    this.frames = 0; // frames received
    this.delay = 250;
    this.connect();
  }

  connect() {
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    const ws = new WebSocket(`${scheme}://${location.host}/ws`);
    ws.onopen = () => {
      this.delay = 250;
      this.onState(true);
    };
    ws.onmessage = (ev) => {
      this.latestText = ev.data;
      this.frames++;
    };
    ws.onclose = () => {
      this.onState(false);
      setTimeout(() => this.connect(), this.delay);
      this.delay = Math.min(this.delay * 2, 5000);
    };
    this.ws = ws;
  }

  /** The newest snapshot received since the last call, parsed, or null. */
  take() {
    const text = this.latestText;
    if (text === null) return null;
    this.latestText = null;
    return JSON.parse(text);
  }
}
