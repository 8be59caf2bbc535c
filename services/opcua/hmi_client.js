"use strict";
// cnc-opcua's way into the cell: the HMI's documented API (docs/hmi-api.md) as any
// client uses it. POST /login as the configured user (the session cookie), then the
// WebSocket /ws with it; `hello`, `status`, `alarms` and `alarm` come to the listeners.
// A closed socket is opened again every second (a restarted HMI: logged in again).
// checkLogin() asks the HMI whether a user name and password are right, by the same
// POST /login (and /logout of the session it made): the HMI's users are OPC UA's.
const http = require("node:http");
const { EventEmitter } = require("node:events");
const WebSocket = require("ws");

const kCookie = "cnc_hmi";

// POST `path` with a form; resolves {status, cookie}.
function post(base, path, form, cookie) {
  return new Promise((resolve, reject) => {
    const body = new URLSearchParams(form).toString();
    const u = new URL(path, base);
    const headers = { "Content-Type": "application/x-www-form-urlencoded", "Content-Length": Buffer.byteLength(body) };
    if (cookie) headers.Cookie = cookie;
    const req = http.request(u, { method: "POST", headers, timeout: 10000 }, (res) => {
      res.resume();
      const set = [].concat(res.headers["set-cookie"] || []).find((c) => c.startsWith(kCookie + "="));
      const value = set ? set.split(";")[0] : "";
      res.on("end", () => resolve({ status: res.statusCode, cookie: value.endsWith("=") ? "" : value }));
    });
    req.on("timeout", () => req.destroy(new Error(`${u.href}: no answer in 10 s`)));
    req.on("error", reject);
    req.end(body);
  });
}

class HmiClient extends EventEmitter {
  // settings: {url, login, view_without_login, user, password}
  constructor(settings, log) {
    super();
    this.s = settings;
    this.log = log;
    this.ws = null;
    this.cookie = "";
    this.connected = false;
    this.stopped = false;
    this.timer = null;
    this.lastWarning = "";
    this.lastWarningAt = 0;
  }

  // A warning once, and again every minute while it holds (the HMI away: one a second).
  warn(text) {
    if (this.stopped) return;
    const now = Date.now();
    if (text === this.lastWarning && now - this.lastWarningAt < 60000) return;
    this.lastWarning = text;
    this.lastWarningAt = now;
    this.log.warn(text);
  }

  start() { this.connect(); }

  stop() {
    this.stopped = true;
    clearTimeout(this.timer);
    if (this.ws) this.ws.terminate();
  }

  async connect() {
    if (this.stopped) return;
    try {
      if (this.s.login && this.s.user && !this.cookie) {
        const r = await post(this.s.url, "/login", { user: this.s.user, password: this.s.password });
        if (r.status !== 303 || !r.cookie)
          throw new Error(`the HMI refused the login of '${this.s.user}' (HTTP ${r.status}): opcua.hmi_user, opcua.hmi_password_file`);
        this.cookie = r.cookie;
      }
      const ws = new WebSocket(this.s.url.replace(/^http/, "ws") + "/ws",
                               { headers: this.cookie ? { Cookie: this.cookie } : {}, handshakeTimeout: 10000 });
      this.ws = ws;
      ws.on("unexpected-response", (req, res) => {
        // 401: the HMI restarted and forgot the session; log in again.
        if (res.statusCode === 401) this.cookie = "";
        this.warn(`cnc-opcua: the HMI refused the WebSocket (HTTP ${res.statusCode})`);
        ws.terminate();
      });
      ws.on("open", () => {
        this.connected = true;
        this.lastWarning = "";
        this.log.info(`cnc-opcua: connected to the HMI at ${this.s.url}${this.s.user && this.s.login ? " as " + this.s.user : ""}`);
        this.emit("connected");
      });
      ws.on("message", (data) => {
        let m;
        try {
          m = JSON.parse(data.toString());
        } catch (e) {
          this.log.warn(`cnc-opcua: the HMI sent no JSON: ${e.message}`);
          return;
        }
        if (typeof m.t === "string") this.emit(m.t, m);
      });
      ws.on("close", () => this.closed());
      ws.on("error", (e) => this.warn(`cnc-opcua: the HMI's WebSocket at ${this.s.url}: ${e.message} (trying again every second)`));
    } catch (e) {
      this.warn(`cnc-opcua: ${e.message} (trying again every second)`);
      this.retry();
    }
  }

  closed() {
    if (this.stopped) return;
    if (this.connected) {
      this.connected = false;
      this.log.warn("cnc-opcua: the HMI's WebSocket closed; the values are marked BadNoCommunication until it is back");
      this.emit("disconnected");
    }
    this.retry();
  }

  retry() {
    if (this.stopped) return;
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.connect(), 1000);
  }

  // True when the HMI takes this user name and password (its users file). The
  // session the check made is logged out at once.
  async checkLogin(user, password) {
    const r = await post(this.s.url, "/login", { user, password });
    if (r.status === 303 && r.cookie) {
      await post(this.s.url, "/logout", {}, r.cookie).catch(() => {});
      return true;
    }
    if (r.status !== 401) this.log.warn(`cnc-opcua: login check of '${user}': HTTP ${r.status} from the HMI`);
    return false;
  }
}

module.exports = { HmiClient };
