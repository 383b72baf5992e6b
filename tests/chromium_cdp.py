"""A headless Chromium driven through the DevTools protocol over a pipe (``--remote-debugging-pipe``:
JSON messages ending in a NUL byte, commands on the browser's fd 3, answers on its fd 4), so that
a test can load a page, move the real mouse over it, read the DOM and take screenshots without a
websocket client or a WebDriver.

Used by the report tests and ``benchmarks/golden_report.py``; the standard library only.
"""

from __future__ import annotations

import base64
import json
import os
import select
import subprocess
import time
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run")


class CDPError(RuntimeError):
    pass


class Browser:
    """One headless Chromium with a fresh profile in ``user_dir`` and one page (a tab)."""

    def __init__(self, user_dir, width=1280, height=800, timeout=60.0):
        self.timeout = timeout
        user_dir = Path(user_dir)
        user_dir.mkdir(parents=True, exist_ok=True)
        cmd_r, self._cmd_w = os.pipe()
        self._out_r, out_w = os.pipe()
        self._log = open(user_dir / "chromium.log", "wb")
        args = [str(CHROMIUM), *FLAGS, f"--user-data-dir={user_dir / 'profile'}",
                "--remote-debugging-pipe", f"--window-size={width},{height}",
                "--hide-scrollbars", "about:blank"]
        # bash moves the pipe ends to the descriptors Chromium expects (3: commands, 4: answers;
        # dash takes one-digit descriptors only)
        self.proc = subprocess.Popen(
            ["/bin/bash", "-c", f'exec "$0" "$@" 3<&{cmd_r} 4>&{out_w}', *args],
            pass_fds=(cmd_r, out_w), stdin=subprocess.DEVNULL, stdout=self._log,
            stderr=self._log)
        os.close(cmd_r)
        os.close(out_w)
        self._buf = b""
        self._id = 0
        self.events = []
        try:
            targets = self.send("Target.getTargets")["targetInfos"]
            page = next(t for t in targets if t["type"] == "page")
            self.session = self.send("Target.attachToTarget",
                                     {"targetId": page["targetId"], "flatten": True})["sessionId"]
            for domain in ("Page", "Runtime"):
                self.call(f"{domain}.enable")
            self.call("Emulation.setDeviceMetricsOverride",
                      {"width": width, "height": height, "deviceScaleFactor": 1,
                       "mobile": False})
        except BaseException:
            self.close()
            raise

    # --- the protocol ---------------------------------------------------------------------------
    def _read(self, deadline):
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise CDPError("no answer from Chromium in time")
            ready, _, _ = select.select([self._out_r], [], [], left)
            if ready:
                chunk = os.read(self._out_r, 1 << 20)
                if not chunk:
                    raise CDPError("Chromium closed the DevTools pipe")
                self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def send(self, method, params=None, session=None):
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._cmd_w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + self.timeout
        while True:
            answer = self._read(deadline)
            if answer.get("id") == self._id:
                if "error" in answer:
                    raise CDPError(f"{method}: {answer['error']}")
                return answer.get("result", {})
            self.events.append(answer)

    def call(self, method, params=None):
        return self.send(method, params, self.session)

    def wait_event(self, method, timeout=None):
        deadline = time.monotonic() + (timeout or self.timeout)
        for i, e in enumerate(self.events):
            if e.get("method") == method:
                return self.events.pop(i)
        while True:
            e = self._read(deadline)
            if e.get("method") == method:
                return e
            self.events.append(e)

    # --- conveniences ---------------------------------------------------------------------------
    def open(self, url):
        """Load ``url``; return the wall time (s) from the navigation command to the load event."""
        self.events = [e for e in self.events if e.get("method") != "Page.loadEventFired"]
        t0 = time.perf_counter()
        self.call("Page.navigate", {"url": url})
        self.wait_event("Page.loadEventFired")
        return time.perf_counter() - t0

    def js(self, expression, await_promise=False):
        """The JSON value of ``expression`` evaluated in the page."""
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                           "awaitPromise": await_promise})
        if "exceptionDetails" in r:
            raise CDPError(f"{expression[:80]}…: {r['exceptionDetails']}")
        return r["result"].get("value")

    def mouse_move(self, x, y):
        self.call("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x, "y": y})

    def screenshot(self):
        """(H, W, 3) uint8 of the viewport."""
        import imageio.v3 as iio
        data = self.call("Page.captureScreenshot", {"format": "png"})["data"]
        return iio.imread(base64.b64decode(data), extension=".png")[..., :3]

    def console(self):
        """Console messages and uncaught exceptions seen so far."""
        out = []
        for e in self.events:
            if e.get("method") == "Runtime.consoleAPICalled":
                out.append(" ".join(str(a.get("value", a.get("description", "")))
                                    for a in e["params"]["args"]))
            elif e.get("method") == "Runtime.exceptionThrown":
                out.append(e["params"]["exceptionDetails"].get("text", "exception"))
        return out

    def close(self):
        try:
            if self.proc.poll() is None:
                try:
                    self.send("Browser.close")
                except (CDPError, OSError):
                    pass
                try:
                    self.proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
        finally:
            for fd in (self._cmd_w, self._out_r):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self._log.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
