// REST client for the airroads API: JSON in and out, errors as ApiError, and the access token
// (asked for once on a 401, kept in sessionStorage, sent as `Authorization: Bearer …` on changes).

const TOKEN_KEY = "airroads.token";

/** An error answered by the API: `{"error": {"code", "message", "field", ...}}` with its status. */
export class ApiError extends Error {
  constructor(status, body) {
    const e = (body && body.error) || {};
    super(e.message || `HTTP ${status}`);
    this.status = status;
    this.code = e.code || "http_error";
    this.field = e.field ?? null;
    this.details = e;
  }
}

export class Api {
  /** @param {() => Promise<string|null>} askToken shows the token form; null when cancelled. */
  constructor(askToken) {
    this.askToken = askToken;
  }

  get token() {
    return sessionStorage.getItem(TOKEN_KEY);
  }

  /** Asks for the token; concurrent 401s share one question. */
  newToken(refused) {
    if (!this.asking) {
      this.asking = this.askToken(refused).then((token) => {
        if (token) sessionStorage.setItem(TOKEN_KEY, token);
        this.asking = null;
        return token;
      });
    }
    return this.asking;
  }

  /** Sends a request; a change refused for want of a token asks for one unless `ask` is false. */
  async request(method, path, body, ask = true) {
    const change = method !== "GET";
    for (let attempt = 0; ; attempt++) {
      const headers = {};
      const sent = this.token;
      // Every change says it is JSON, also without a body: the server refuses others (a page on
      // another origin can only send those without asking the server first).
      if (body !== undefined || change) headers["Content-Type"] = "application/json";
      if (change && sent) headers["Authorization"] = `Bearer ${sent}`;
      const text = typeof body === "string" ? body : JSON.stringify(body);
      const res = await fetch(path, { method, headers, body: body === undefined ? undefined : text });
      if (res.status === 401 && change && attempt === 0 && ask) {
        // Another request may have been given a token meanwhile: retry with it, else ask.
        if (this.token && this.token !== sent) continue;
        if (await this.newToken(sent !== null)) continue;
      }
      const raw = await res.text();
      let json = null;
      try {
        json = raw ? JSON.parse(raw) : null;
      } catch {
        json = null;
      }
      if (!res.ok) throw new ApiError(res.status, json);
      return json;
    }
  }

  state() { return this.request("GET", "/api/state"); }
  metrics() { return this.request("GET", "/api/metrics"); }
  road() { return this.request("GET", "/api/road"); }
  geometry() { return this.request("GET", "/api/road/geometry"); }
  policies() { return this.request("GET", "/api/policies"); }
  uav(id) { return this.request("GET", `/api/uavs/${encodeURIComponent(id)}`); }
  /** The UAVs Rerun logs one by one in a batched fleet (view state: never asks for a token). */
  rerunSelection(ids) { return this.request("PUT", "/api/rerun/selection", { ids }, false); }
  putRoad(layout) { return this.request("PUT", "/api/road", layout); }
  addUav(id, position, policy) { return this.request("POST", "/api/uavs", { id, position, policy }); }
  removeUav(id) { return this.request("DELETE", `/api/uavs/${encodeURIComponent(id)}`); }
  setGoal(id, goal) { return this.request("PUT", `/api/uavs/${encodeURIComponent(id)}/goal`, { goal }); }
  setPolicy(id, policy) { return this.request("PUT", `/api/uavs/${encodeURIComponent(id)}/policy`, { policy }); }
  /** @param {string} text the scenario file as it is (the server validates it). */
  loadScenario(text) { return this.request("POST", "/api/scenario", text); }
  pause() { return this.request("POST", "/api/fleet/pause"); }
  resume() { return this.request("POST", "/api/fleet/resume"); }
  land(id) { return this.request("POST", `/api/uavs/${encodeURIComponent(id)}/land`); }
  landAll() { return this.request("POST", "/api/fleet/land"); }
  emergencyStop() { return this.request("POST", "/api/fleet/stop"); }
}
