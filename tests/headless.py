"""A headless Chromium driven over the DevTools protocol on a pipe, with the standard library only.

Used by the browser tests of the overview map and the compare report (they skip when no
Chromium is installed: :func:`chromium_path`), and run as a script it makes the screenshots
of the docs::

    python tests/headless.py docs/images     # drive_map.png and compare_report.png

Chromium is started with ``--remote-debugging-pipe``: it reads protocol messages (JSON, each
ended by a NUL byte) on its fd 3 and writes on its fd 4.  The browser resolves no host names
(``--host-resolver-rules``), so a page is offline whatever the machine's network, unless a
test serves the requests itself (:meth:`Page.serve`).
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: Executables tried in this order (``NAVPP_CHROMIUM`` first when set).
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def chromium_path() -> str | None:
    """The Chromium executable to use, or None when there is none."""
    env = os.environ.get("NAVPP_CHROMIUM")
    if env:
        return env if os.path.isfile(env) and os.access(env, os.X_OK) else None
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


class BrowserError(RuntimeError):
    """The browser closed, timed out or answered a command with an error."""


class Browser:
    """One headless Chromium process; a context manager that closes it (and its profile)."""

    def __init__(self, exe: str, timeout_s: float = 30.0) -> None:
        self.timeout_s = timeout_s
        self.profile = tempfile.mkdtemp(prefix="navpp-chromium-")
        to_child_r, self._w = os.pipe()
        self._r, from_child_w = os.pipe()

        def fds() -> None:            # the protocol's fds 3 (commands) and 4 (answers)
            a, b = os.dup(to_child_r), os.dup(from_child_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        args = [exe, "--headless", "--remote-debugging-pipe", "--no-sandbox", "--disable-gpu",
                "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                "--host-resolver-rules=MAP * ~NOTFOUND", "--hide-scrollbars", "--force-device-scale-factor=1",
                f"--user-data-dir={self.profile}", "about:blank"]
        self.proc = subprocess.Popen(args, preexec_fn=fds, pass_fds=(3, 4), stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self._buf = b""
        self._id = 0
        self.events: list[dict[str, Any]] = []
        self.pages: list[Page] = []

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self.proc.poll() is None:
            with contextlib.suppress(BrowserError, OSError):
                self._send("Browser.close")
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for fd in (self._r, self._w):
            with contextlib.suppress(OSError):
                os.close(fd)
        shutil.rmtree(self.profile, ignore_errors=True)

    def _send(self, method: str, params: dict[str, Any] | None = None, session: str | None = None) -> dict[str, Any]:
        self._id += 1
        want = self._id
        msg: dict[str, Any] = {"id": want, "method": method, "params": params or {}}
        if session is not None:
            msg["sessionId"] = session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        while True:
            m = self._next(time.monotonic() + self.timeout_s)
            if m.get("id") == want:
                if "error" in m:
                    raise BrowserError(f"{method}: {m['error']}")
                return m.get("result", {})
            self._event(m)

    def _event(self, m: dict[str, Any]) -> None:
        self.events.append(m)
        for page in self.pages:
            if m.get("sessionId") == page.session:
                page.on_event(m)

    def _next(self, deadline: float) -> dict[str, Any]:
        import select

        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._r], [], [], left)[0]:
                raise BrowserError("no answer from the browser")
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise BrowserError("the browser closed")
            self._buf += chunk
        raw, _, self._buf = self._buf.partition(b"\0")
        return json.loads(raw)

    def pump(self, seconds: float) -> None:
        """Handle events for ``seconds``."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                self._event(self._next(deadline))
            except BrowserError as exc:
                if "no answer" in str(exc):
                    return
                raise

    def page(self, width: int = 1100, height: int = 760) -> Page:
        """A new tab of ``width`` x ``height`` CSS px (device scale 1)."""
        target = self._send("Target.createTarget", {"url": "about:blank"})
        session = self._send("Target.attachToTarget", {"targetId": target["targetId"], "flatten": True})["sessionId"]
        page = Page(self, session)
        for domain in ("Page", "Runtime", "Log"):
            page.send(f"{domain}.enable")
        page.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                          "mobile": False})
        return page


class Page:
    """One tab: navigate, evaluate JavaScript, send input, serve requests, take screenshots.

    ``errors``: the page's uncaught exceptions and console errors (not failed network loads,
    listed in ``failed_loads``)."""

    def __init__(self, browser: Browser, session: str) -> None:
        self.browser, self.session = browser, session
        self.errors: list[str] = []
        self.failed_loads: list[str] = []
        self.requests: list[tuple[str, dict[str, str]]] = []
        self.loaded = False
        self._serve: Callable[[str], tuple[int, str, bytes] | None] | None = None
        browser.pages.append(self)

    def send(self, method: str, params: dict[str, Any] | None = None) -> dict[str, Any]:
        return self.browser._send(method, params, self.session)

    def on_event(self, m: dict[str, Any]) -> None:
        method, p = m.get("method"), m.get("params", {})
        if method == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            self.errors.append(d.get("exception", {}).get("description") or d.get("text", "exception"))
        elif method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            self.errors.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
        elif method == "Log.entryAdded":
            e = p.get("entry", {})
            if e.get("source") == "network":
                self.failed_loads.append(e.get("url", ""))
            elif e.get("level") == "error":
                self.errors.append(e.get("text", ""))
        elif method == "Page.loadEventFired":
            self.loaded = True
        elif method == "Fetch.requestPaused" and self._serve is not None:
            url = p["request"]["url"]
            self.requests.append((url, dict(p["request"].get("headers", {}))))
            answer = None if url.startswith("file:") else self._serve(url)
            if url.startswith("file:"):          # local files load as they are
                cmd = {"method": "Fetch.continueRequest", "params": {"requestId": p["requestId"]}}
            elif answer is None:
                cmd = {"method": "Fetch.failRequest",
                       "params": {"requestId": p["requestId"], "errorReason": "NameNotResolved"}}
            else:
                status, ctype, body = answer
                cmd = {"method": "Fetch.fulfillRequest",
                       "params": {"requestId": p["requestId"], "responseCode": status,
                                  "responseHeaders": [{"name": "Content-Type", "value": ctype}],
                                  "body": base64.b64encode(body).decode("ascii")}}
            # answered from inside the event handler: only queue the command, the reply comes later
            self.browser._id += 1
            os.write(self.browser._w, json.dumps({"id": self.browser._id, "sessionId": self.session, **cmd}).encode()
                     + b"\0")

    def serve(self, pattern: str, handler: Callable[[str], tuple[int, str, bytes] | None]) -> None:
        """Answer the requests whose URL matches ``pattern`` (``*`` wildcards) with
        ``handler(url) -> (status, content type, body)``, or fail them as unresolved when it
        returns None (offline); ``file:`` URLs load as usual.  The URLs and headers of the
        requests go to ``requests``."""
        self._serve = handler
        self.send("Fetch.enable", {"patterns": [{"urlPattern": pattern}]})

    def goto(self, where: str | Path, settle_s: float = 0.5) -> None:
        """Open a local file (a path) or a URL (``http...``: see :meth:`serve`) and wait for its
        load event, then ``settle_s`` more."""
        self.loaded = False
        is_url = isinstance(where, str) and where.startswith(("http:", "https:"))
        url = str(where) if is_url else Path(where).resolve().as_uri()
        self.send("Page.navigate", {"url": url})
        deadline = time.monotonic() + self.browser.timeout_s
        while not self.loaded:
            if time.monotonic() > deadline:
                raise BrowserError(f"{url}: no load event")
            self.browser.pump(0.05)
        self.browser.pump(settle_s)

    def js(self, expression: str) -> Any:
        """The value of a JavaScript expression (JSON-able); a thrown exception raises BrowserError."""
        r = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True})
        if "exceptionDetails" in r:
            raise BrowserError(f"{expression[:60]}...: {r['exceptionDetails'].get('text')}")
        return r["result"].get("value")

    def mouse(self, kind: str, x: float, y: float, **extra: Any) -> None:
        """``Input.dispatchMouseEvent`` (``kind``: mousePressed, mouseReleased, mouseMoved, mouseWheel)."""
        self.send("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, **extra})

    def wheel(self, x: float, y: float, delta_y: float) -> None:
        self.mouse("mouseWheel", x, y, deltaX=0, deltaY=delta_y)
        self.browser.pump(0.05)

    def drag(self, x0: float, y0: float, x1: float, y1: float, steps: int = 5) -> None:
        self.mouse("mousePressed", x0, y0, button="left", buttons=1, clickCount=1)
        for k in range(1, steps + 1):
            self.mouse("mouseMoved", x0 + (x1 - x0) * k / steps, y0 + (y1 - y0) * k / steps, button="left", buttons=1)
        self.mouse("mouseReleased", x1, y1, button="left", buttons=0, clickCount=1)
        self.browser.pump(0.05)

    def click(self, x: float, y: float, count: int = 1) -> None:
        for c in range(1, count + 1):
            self.mouse("mousePressed", x, y, button="left", buttons=1, clickCount=c)
            self.mouse("mouseReleased", x, y, button="left", buttons=0, clickCount=c)
        self.browser.pump(0.05)

    def screenshot(self, path: str | Path, full_page: bool = False) -> None:
        params: dict[str, Any] = {"format": "png"}
        if full_page:
            params["captureBeyondViewport"] = True
            size = self.send("Page.getLayoutMetrics")["cssContentSize"]
            params["clip"] = {"x": 0, "y": 0, "width": size["width"], "height": size["height"], "scale": 1}
        Path(path).write_bytes(base64.b64decode(self.send("Page.captureScreenshot", params)["data"]))


#: The figures of the report the screenshot keeps (by caption); the others are hidden to keep it short.
REPORT_SHOT_KEEPS = ("vce-ckf: position error", "overview map")


def docs_screenshots(dest: Path) -> list[Path]:
    """``drive_map.png`` (the sample drive's overview map with vce-ckf and a 30 s GNSS outage)
    and ``compare_report.png`` (the compare report of the sample drive, ekf and vce-ckf: the
    table, one run's error figure and the map; the other figures hidden) into ``dest``."""
    exe = chromium_path()
    if exe is None:
        raise SystemExit("no Chromium found (install chromium or set NAVPP_CHROMIUM)")
    root = Path(__file__).resolve().parents[1]
    work = Path(tempfile.mkdtemp(prefix="navpp-shots-"))
    navpp = [sys.executable, "-m", "navpp"]
    for args in (["process", "sample_data/drive.mcap", "--filter", "vce-ckf", "--gnss-outage", "120:30", "--plot",
                  "--out", str(work / "process")],
                 ["compare", "sample_data/drive.mcap", "--filters", "ekf,vce-ckf", "--out", str(work / "compare")]):
        run = subprocess.run([*navpp, *args], cwd=root, capture_output=True, text=True)
        if run.returncode != 0:
            raise SystemExit(f"navpp {' '.join(args)} failed:\n{run.stderr}")
    dest.mkdir(parents=True, exist_ok=True)
    shots = [dest / "drive_map.png", dest / "compare_report.png"]
    with Browser(exe) as b:
        page = b.page(1100, 700)
        page.goto(work / "process" / "drive.mcap_map.html", settle_s=1.0)
        page.screenshot(shots[0])
        page = b.page(1100, 900)
        page.goto(work / "compare" / "report.html", settle_s=1.5)
        page.js("Array.from(document.querySelectorAll('figure')).forEach(function (f) { "
                f"if (!{list(REPORT_SHOT_KEEPS)!r}.some(function (k) {{ "
                "return f.querySelector('figcaption').textContent.indexOf(k) >= 0; })) { f.style.display = 'none'; } "
                "}); true")
        page.screenshot(shots[1], full_page=True)
    shutil.rmtree(work, ignore_errors=True)
    return shots


if __name__ == "__main__":
    for shot in docs_screenshots(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images")):
        print(f"wrote {shot}")
