"""drake-skill's own teleoperation page: the Meshcat view embedded, the keys and the status owned here.

Why a page of our own (issue 51): Drake's Meshcat binds a slider's keys on its
page with no check of what has focus, so W typed into a slider's number box
also moves the hand, and its API has no way to show text that changes (no
label or text widget). Patching Drake's meshcat.js is not an option. So
``drake-skill demos record --interactive`` serves this small page on the
loopback interface (Python's standard ``http.server``, one thread):

* the Meshcat view fills the right of the page in an ``<iframe>``, its camera
  set behind the robot on the object (``teleop.frame_teleop_view``); its control panel
  keeps the sliders and buttons for the mouse, with no keys bound to them;
* the page's own key handler sends a key to the session only when no text
  box has focus (``typing()`` below), and shows whether keys are live (a click
  into the 3D view gives it the focus: the panel then says to click the panel);
* the left panel shows the session's state, polled every 0.2 s from
  ``GET /status``: idle or recording with its time, demonstration k of n and
  how many are kept, the last verdict and why, and the two time limits;
* a note typed into the panel's box is stored in the demonstration's metadata;
* a closed page (``pagehide`` beacon, or no status poll for
  ``heartbeat_timeout`` s once a page has connected) ends the session as
  Ctrl-C does: every finished demonstration is kept.

Routes: ``GET /`` the page, ``GET /status`` JSON, ``POST /key`` ``{"code":
"KeyW"}``, ``POST /note`` ``{"text": ...}``, ``POST /closed``.
"""

from __future__ import annotations

import html
import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np


class PageClosed(KeyboardInterrupt):
    """The teleoperation page was closed: handled as an interruption (what is finished is kept)."""


class TeleopPage:
    """The page's server and the state it shares with the session (thread-safe).

    axis_keys: per controlled value (7), its (decrement, increment) key codes
    (``KeyboardEvent.code``); record_key, stop_key: the buttons' keys;
    meshcat_url: the view to embed; title: the page's heading.
    """

    def __init__(self, meshcat_url: str, axis_keys, record_key: str, stop_key: str, legend: str = "",
                 title: str = "drake-skill teleoperation", host: str = "127.0.0.1", port: int = 0,
                 heartbeat_timeout: float = 5.0):
        self._lock = threading.Lock()
        self._keys = {}
        for i, (dec, inc) in enumerate(axis_keys):
            self._keys[dec], self._keys[inc] = (i, -1), (i, +1)
        self._buttons = {record_key: 0, stop_key: 1}
        self._steps = np.zeros(len(axis_keys), dtype=int)
        self._clicks = [0, 0]
        self._status: dict = {"mode": "starting"}
        self._note = ""
        self._last_poll: float | None = None
        self._closed = False
        self._key_times: list[tuple[str, float]] = []
        self.heartbeat_timeout = heartbeat_timeout
        self._html = _page_html(meshcat_url, sorted(self._keys) + sorted(self._buttons), legend, title)
        self._server = ThreadingHTTPServer((host, port), _handler(self))
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, name="teleop-page", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}/"

    def close(self) -> None:
        """Stops the server (the page then says the session has ended)."""
        self._server.shutdown()
        self._server.server_close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # The session's side.
    def take_key_steps(self) -> np.ndarray:
        """Net key presses per controlled value since the last call ((7,) int, + increments)."""
        with self._lock:
            steps, self._steps = self._steps, np.zeros_like(self._steps)
        return steps

    def clicks(self) -> tuple[int, int]:
        """(record, stop) key presses since the last :meth:`reset_clicks`."""
        with self._lock:
            return self._clicks[0], self._clicks[1]

    def reset_clicks(self) -> None:
        with self._lock:
            self._clicks = [0, 0]

    def publish(self, **fields) -> None:
        """Merges ``fields`` into the status the page shows (JSON values)."""
        with self._lock:
            self._status.update(fields)

    def status(self) -> dict:
        with self._lock:
            return dict(self._status)

    @property
    def note(self) -> str:
        with self._lock:
            return self._note

    @property
    def closed(self) -> bool:
        """The page said it closed, or stopped polling for ``heartbeat_timeout`` s after connecting."""
        with self._lock:
            stale = self._last_poll is not None and time.monotonic() - self._last_poll > self.heartbeat_timeout
            return self._closed or stale

    def check_open(self) -> None:
        """Raises :class:`PageClosed` if the page was closed."""
        if self.closed:
            raise PageClosed("the teleoperation page was closed")

    def key_times(self) -> list[tuple[str, float]]:
        """(code, time.time() when the server got it) of every key so far (the latency script reads it)."""
        with self._lock:
            return list(self._key_times)

    # The page's side (called from the server thread).
    def _on_key(self, code: str) -> bool:
        with self._lock:
            self._key_times.append((code, time.time()))
            if code in self._keys:
                axis, sign = self._keys[code]
                self._steps[axis] += sign
            elif code in self._buttons:
                self._clicks[self._buttons[code]] += 1
            else:
                return False
            return True

    def _on_poll(self) -> dict:
        with self._lock:
            self._last_poll = time.monotonic()
            return dict(self._status)

    def _on_note(self, text: str) -> None:
        with self._lock:
            self._note = str(text)[:2000]

    def _on_closed(self) -> None:
        with self._lock:
            self._closed = True


def _handler(page: TeleopPage):
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args):           # quiet: the terminal is the session's
            pass

        def _send(self, code: int, body: bytes, kind: str = "application/json") -> None:
            self.send_response(code)
            self.send_header("Content-Type", kind)
            self.send_header("Cache-Control", "no-store")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self):
            if self.path == "/":
                self._send(200, page._html.encode(), "text/html; charset=utf-8")
            elif self.path == "/status":
                self._send(200, json.dumps(page._on_poll()).encode())
            else:
                self._send(404, b"{}")

        def do_POST(self):
            length = min(int(self.headers.get("Content-Length") or 0), 10_000)
            try:
                body = json.loads(self.rfile.read(length) or b"{}")
            except ValueError:
                body = {}
            if self.path == "/key":
                ok = page._on_key(str(body.get("code", "")))
                self._send(200 if ok else 400, b"{}")
            elif self.path == "/note":
                page._on_note(body.get("text", ""))
                self._send(200, b"{}")
            elif self.path == "/closed":
                page._on_closed()
                self._send(200, b"{}")
            else:
                self._send(404, b"{}")

    return Handler


def _page_html(meshcat_url: str, keys: list[str], legend: str, title: str) -> str:
    return _PAGE.replace("__TITLE__", html.escape(title)).replace("__LEGEND__", html.escape(legend)) \
        .replace("__MESHCAT__", html.escape(meshcat_url, quote=True)).replace("__KEYS__", json.dumps(keys))


_PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>__TITLE__</title>
<style>
body { margin: 0; display: flex; height: 100vh; font: 14px system-ui, sans-serif; }
#panel { width: 300px; padding: 12px; box-sizing: border-box; overflow: auto; background: #f4f4f4; }
#view { flex: 1; border: 0; }
#mode { font-size: 22px; font-weight: 600; padding: 6px 8px; border-radius: 4px; background: #ddd; }
#mode.recording { background: #d33; color: white; } #mode.idle { background: #ccc; }
#mode.done { background: #36a; color: white; } #mode.ended { background: #888; color: white; }
.ok { color: #170; } .bad { color: #b00; } .dim { color: #666; }
#keys.live { color: #170; } #keys.off { color: #b60; font-weight: 600; }
pre { white-space: pre-wrap; font-size: 12px; } textarea { width: 100%; box-sizing: border-box; }
</style></head>
<body>
<div id="panel" tabindex="-1">
  <h3>__TITLE__</h3>
  <div id="mode">connecting</div>
  <p id="demo"></p>
  <p id="last"></p>
  <p id="limits" class="dim"></p>
  <p id="keys" class="live">keys: live</p>
  <pre>__LEGEND__</pre>
  <label for="note">note for this demonstration</label>
  <textarea id="note" rows="2"></textarea>
  <pre id="log" class="dim"></pre>
</div>
<iframe id="view" src="__MESHCAT__"></iframe>
<script>
const KEYS = new Set(__KEYS__);
const $ = (id) => document.getElementById(id);
function typing() {
  const el = document.activeElement;
  return !!el && (["INPUT", "TEXTAREA", "SELECT"].includes(el.tagName) || el.isContentEditable);
}
document.addEventListener("keydown", (e) => {
  if (typing() || !KEYS.has(e.code) || e.ctrlKey || e.metaKey || e.altKey) return;
  e.preventDefault();
  fetch("/key", {method: "POST", body: JSON.stringify({code: e.code})});
});
$("note").addEventListener("input", () =>
  fetch("/note", {method: "POST", body: JSON.stringify({text: $("note").value})}));
$("panel").addEventListener("mousedown", (e) => {
  if (e.target.id !== "note") setTimeout(() => $("panel").focus(), 0);
});
addEventListener("pagehide", () => navigator.sendBeacon("/closed", "{}"));
function keysState() {
  const k = $("keys");
  if (typing()) { k.className = "off"; k.textContent = "keys: off while a text box has focus"; }
  else if (document.activeElement === $("view") || !document.hasFocus()) {
    k.className = "off"; k.textContent = "keys: off (the 3D view has focus); click this panel"; }
  else { k.className = "live"; k.textContent = "keys: live"; }
}
for (const event of ["focusin", "focusout"]) document.addEventListener(event, () => setTimeout(keysState, 0));
addEventListener("blur", () => setTimeout(keysState, 0));
function fmt(s) { return s == null ? "" : Number(s).toFixed(1); }
function render(s) {
  const m = $("mode");
  m.className = s.mode;
  m.textContent = s.mode === "recording" ? "recording " + fmt(s.recording_s) + " s" : s.mode;
  $("demo").textContent = s.count ? "demonstration " + s.demo + " of " + s.count + " (kept " + (s.kept || 0) + ")" : "";
  const last = $("last");
  if (s.last_verdict) {
    last.className = s.last_verdict === "success" ? "ok" : "bad";
    last.textContent = "last: " + s.last_verdict + " (" + (s.last_why || "") + ")";
  }
  if (s.max_wait != null)
    $("limits").textContent = "press Record within " + fmt(s.max_wait) + " s" +
      (s.wait_left == null ? "" : " (" + fmt(s.wait_left) + " s left)") +
      "; a recording stops by itself after " + fmt(s.max_duration) + " s";
  $("log").textContent = (s.log || []).join("\\n");
}
async function poll() {
  try { render(await (await fetch("/status", {cache: "no-store"})).json()); }
  catch (err) { $("mode").className = "ended"; $("mode").textContent = "the session has ended"; }
  keysState();
}
setInterval(poll, 200); poll();
</script>
</body></html>
"""
