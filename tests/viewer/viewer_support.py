"""Helpers of the viewer tests: a minimal viser protocol client (no browser), waiting.

The protocol client follows notes/libraries.md section 1.8: connect with the
``viser-v<version>`` subprotocol, send a camera message (a browser is only registered as
a client after its first camera message), then send ``GuiUpdateMessage``s as the page
does when a control is used. It drains what the server sends in a background thread so
the server never blocks on a full socket. It uses viser's private message classes, which
is why ``viser`` is pinned to one version in pyproject.toml.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec
import viser
from viser import _messages
from websockets.sync.client import connect


class ProtocolClient:
    """A fake browser tab connected to a viser server on 127.0.0.1.

    Parameters
    ----------
    port
        The server's port.
    path
        Request target of the handshake (e.g. ``/?token=...`` for a server with a token).
    """

    def __init__(self, port: int, path: str = "") -> None:
        self.ws = connect(
            f"ws://127.0.0.1:{port}{path}",
            subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
            max_size=None,
        )
        self.received = 0
        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()
        self.send(
            _messages.ViewerCameraMessage(
                wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 1.0, 3.0), fov=1.0, near=0.01, far=100.0,
                image_height=360, image_width=480, look_at=(0.0, 1.0, 0.0), up_direction=(0.0, 1.0, 0.0),
            )
        )

    def _drain(self) -> None:
        while not self._stop.is_set():
            try:
                self.ws.recv(timeout=0.2)
                self.received += 1
            except TimeoutError:
                continue
            except Exception:  # noqa: BLE001 - connection closed
                return

    def send(self, message: Any) -> None:
        """Send one viser message object."""
        self.ws.send(msgspec.msgpack.encode(message.as_serializable_dict()))

    def set_value(self, handle: Any, value: Any) -> None:
        """Change a control's value as the page does (for a button or a button group:
        ``True`` or the clicked option)."""
        self.send(_messages.GuiUpdateMessage(uuid=handle._impl.uuid, updates={"value": value}))

    def close(self) -> None:
        """Disconnect."""
        self._stop.set()
        self.ws.close()
        self._reader.join(timeout=2.0)


def wait_for(predicate: Callable[[], Any], timeout: float = 60.0, what: str = "condition") -> Any:
    """Poll ``predicate`` until it returns something truthy; fail after ``timeout`` s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


class ViewProcess:
    """``addb view ARGS`` in a subprocess, as the console script runs it.

    Starts the command, reads its output until it says "first frame shown" (or exits) and
    keeps the printed address in :attr:`url`; a thread keeps reading the rest into
    :attr:`lines`. :meth:`stop` sends SIGTERM and asserts a clean exit.

    Parameters
    ----------
    args
        The arguments after ``addb view``.
    cwd
        Working folder; the user cache (``XDG_CACHE_HOME``) goes to ``cwd/cache``.
    url_pattern
        Regular expression of the address in the output (group 1).
    """

    def __init__(self, args: list[str], cwd: Any, url_pattern: str = r" at (http://127\.0\.0\.1:\d+)") -> None:
        import os
        import re
        import subprocess
        import sys
        from pathlib import Path

        repo = Path(__file__).resolve().parents[2]
        env = dict(os.environ, XDG_CACHE_HOME=str(Path(cwd) / "cache"), PYTHONPATH=str(repo))
        cmd = [sys.executable, "-m", "addb_viewer.cli", "view", *args]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=cwd)
        self.lines: list[str] = []
        self.url: str | None = None
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)
            m = re.search(url_pattern, line)
            self.url = self.url or (m.group(1) if m else None)
            if "first frame shown" in line or self.proc.poll() is not None:
                break
        assert self.url, "".join(self.lines)
        threading.Thread(target=lambda: self.lines.extend(self.proc.stdout), daemon=True).start()

    @property
    def output(self) -> str:
        """Everything the process printed so far."""
        return "".join(self.lines)

    def stop(self) -> None:
        """SIGTERM, then assert the process exited with 0 (killed after 60 s)."""
        import signal
        import subprocess

        self.proc.send_signal(signal.SIGTERM)
        try:
            assert self.proc.wait(60) == 0, self.output
        except subprocess.TimeoutExpired:
            self.proc.kill()
            raise
