"""A screenshot of a page in headless Chromium after it has run for a while in real time.

`chromium --screenshot` shoots when its virtual time budget ends, and rerun's web viewer compiles
its WebAssembly outside virtual time: the shot shows the loading page. So Chromium is driven over
the DevTools protocol on a pipe (`--remote-debugging-pipe`: JSON messages ending in a NUL byte,
commands on fd 3, answers on fd 4), which needs no websocket library: open the page, wait, shoot.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from stack.apps.view import stop

FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
)
"""Headless, no network beyond the page, WebGL in software (SwiftShader)."""


def chromium() -> str | None:
    """The Chromium program on PATH (None: not installed)."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


class Pipe:
    """The DevTools protocol over Chromium's debugging pipe."""

    def __init__(self, to_browser: int, from_browser: int) -> None:
        self.to_browser, self.from_browser = to_browser, from_browser
        self.buffer = b""
        self.next_id = 0

    def call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        """Send one command and wait for its answer (events in between are dropped)."""
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if session is not None:
            message["sessionId"] = session
        os.write(self.to_browser, json.dumps(message).encode() + b"\0")
        while True:
            while b"\0" not in self.buffer:
                chunk = os.read(self.from_browser, 1 << 20)
                if not chunk:
                    raise RuntimeError("chromium closed its debugging pipe")
                self.buffer += chunk
            raw, self.buffer = self.buffer.split(b"\0", 1)
            answer = json.loads(raw)
            if answer.get("id") == self.next_id:
                if "error" in answer:
                    raise RuntimeError(f"{method}: {answer['error']}")
                return answer.get("result", {})


def screenshot(url: str, path: Path, wait_s: float, size: tuple[int, int] = (1600, 1000)) -> Path:
    """`url` rendered in a `size` window [px] after `wait_s` seconds, as a PNG at `path`."""
    program = chromium()
    assert program is not None, "chromium is not installed"
    commands_read, commands_write = os.pipe()
    answers_read, answers_write = os.pipe()

    def wire() -> None:  # in the child, before exec: fd 3 reads commands, fd 4 writes answers
        ends = [fcntl.fcntl(end, fcntl.F_DUPFD, 10) for end in (commands_read, answers_write)]  # never 3 or 4
        os.dup2(ends[0], 3)
        os.dup2(ends[1], 4)

    with tempfile.TemporaryDirectory() as profile:
        browser = subprocess.Popen(
            [
                program,
                *FLAGS,
                f"--user-data-dir={profile}",
                f"--window-size={size[0]},{size[1]}",
                "--remote-debugging-pipe",
                "about:blank",
            ],
            close_fds=False,
            preexec_fn=wire,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        os.close(commands_read)
        os.close(answers_write)
        try:
            pipe = Pipe(commands_write, answers_read)
            target = pipe.call("Target.createTarget", {"url": url})["targetId"]
            session = pipe.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
            time.sleep(wait_s)
            shot = pipe.call("Page.captureScreenshot", {"format": "png"}, session)
            path.write_bytes(base64.b64decode(shot["data"]))
        finally:
            stop(browser, grace_s=10.0)
            os.close(commands_write)
            os.close(answers_read)
    return path
