"""A screenshot of a web page after it has run for a while, in headless Chromium.

    python -m herb_client.screenshot URL out.png [--wait 20] [--size 1400x900] [--scale 1]

Chromium's own ``--screenshot`` shoots as soon as the page has loaded, before a WebAssembly
application such as Rerun's web viewer has started. This drives Chromium over its DevTools
protocol on a pipe (``--remote-debugging-pipe``: standard library only, no browser driver) and
shoots after ``--wait`` seconds. Software rendering (SwiftShader), so it needs no GPU. The page
is laid out at ``--size`` and drawn at ``--scale`` times it: a scale of 0.5 gives the same
picture at a quarter of the pixels, which the software renderer draws faster (Rerun's viewer at
1400 x 900 on 2 cores: a screenshot in 1.4 to 2.0 s instead of about 4.5 s).
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import subprocess
import sys
import time


class Chromium:
    """A headless Chromium driven over the DevTools pipe: pages laid out at ``width`` x
    ``height`` CSS pixels, drawn at ``scale`` device pixels per CSS pixel."""

    def __init__(self, width: int, height: int, exe: str | None = None, scale: float = 1.0):
        if not scale > 0.0:
            raise ValueError(f"scale must be positive, not {scale}")
        exe = exe or shutil.which("chromium") or shutil.which("chromium-browser")
        if exe is None:
            raise SystemExit("chromium not found (Debian: apt install chromium)")
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        args = [
            exe,
            "--headless=new",
            "--no-sandbox",
            "--remote-debugging-pipe",
            "--enable-unsafe-swiftshader",
            "--use-angle=swiftshader",
            "--no-first-run",
            f"--window-size={width},{height}",
            f"--force-device-scale-factor={scale}",
            "about:blank",
        ]
        # Chromium reads the protocol on fd 3 and writes on fd 4: a trampoline puts the pipes
        # there (moved above 9 first, so that neither overwrites the other) and execs it.
        tramp = (
            "import fcntl, os, sys\n"
            "r, w = (fcntl.fcntl(int(f), fcntl.F_DUPFD, 10) for f in sys.argv[1:3])\n"
            "os.dup2(r, 3)\n"
            "os.dup2(w, 4)\n"
            "os.execvp(sys.argv[3], sys.argv[3:])\n"
        )
        self.proc = subprocess.Popen(
            [sys.executable, "-c", tramp, str(to_child_r), str(from_child_w), *args],
            pass_fds=(to_child_r, from_child_w),
            stdout=subprocess.DEVNULL,
            stderr=open(os.environ.get("HERB_CHROMIUM_LOG", os.devnull), "w"),
        )
        os.close(to_child_r)
        os.close(from_child_w)
        self._id = 0
        self._buf = b""

    def call(self, method: str, session: str | None = None, **params) -> dict:
        """Sends one command and returns its result (events in between are skipped)."""
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self._to_child, json.dumps(msg).encode() + b"\0")
        while True:
            while b"\0" not in self._buf:
                chunk = os.read(self._from_child, 1 << 16)
                if not chunk:
                    raise RuntimeError(f"chromium closed the pipe during {method}")
                self._buf += chunk
            raw, self._buf = self._buf.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def close(self) -> None:
        try:
            self.call("Browser.close")
        except Exception:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


class Page:
    """A page open in a [`Chromium`], to be shot later (it keeps running meanwhile)."""

    def __init__(self, browser: Chromium, url: str):
        self.browser = browser
        target = browser.call("Target.createTarget", url=url)["targetId"]
        self.session = browser.call("Target.attachToTarget", targetId=target, flatten=True)[
            "sessionId"
        ]
        browser.call("Page.enable", session=self.session)

    def shoot(self, out: str) -> None:
        """Writes a PNG of the page as it is now."""
        shot = self.browser.call("Page.captureScreenshot", session=self.session, format="png")
        with open(out, "wb") as f:
            f.write(base64.b64decode(shot["data"]))


def screenshot(
    url: str, out: str, wait_s: float = 20.0, width: int = 1400, height: int = 900, scale: float = 1.0
) -> None:
    """Opens ``url``, lets it run ``wait_s`` seconds, writes a PNG of the page to ``out``."""
    c = Chromium(width, height, scale=scale)
    try:
        page = Page(c, url)
        time.sleep(wait_s)
        page.shoot(out)
    finally:
        c.close()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("url")
    ap.add_argument("out")
    ap.add_argument("--wait", type=float, default=20.0, help="seconds to let the page run")
    ap.add_argument("--size", default="1400x900", help="window size, WIDTHxHEIGHT")
    ap.add_argument("--scale", type=float, default=1.0, help="device pixels per CSS pixel (0.5: a quarter of the pixels)")
    a = ap.parse_args(argv)
    try:
        w, h = (int(v) for v in a.size.split("x"))
    except ValueError:
        ap.error(f"--size: not WIDTHxHEIGHT: {a.size!r}")
    if not a.scale > 0.0:
        ap.error(f"--scale: must be positive, not {a.scale}")
    screenshot(a.url, a.out, a.wait, w, h, a.scale)
    return 0


if __name__ == "__main__":
    sys.exit(main())
