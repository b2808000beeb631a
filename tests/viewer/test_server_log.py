"""The review server does not log a browser's unused spare connections as failed handshakes
(:mod:`addb_viewer.app.server_log`).

Found by ``test_viewer_browser.py::test_review_in_the_browser`` on a fresh clone: Chromium
closed a preconnected socket without a request and the websockets server under viser
printed a three-part traceback on the app's terminal. viser drops every handshake failure
once its server has answered one HTTP request, so the real-server check runs in a fresh
process and opens the unused connection before any request."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest
from websockets.server import ServerProtocol

from addb_viewer.app.server_log import WEBSOCKETS_SERVER_LOGGER, is_unused_connection

REPO = Path(__file__).resolve().parents[2]


def _handshake_record(data: bytes) -> logging.LogRecord:
    """The record websockets' server logs when a connection sends ``data`` and closes: the
    handshake error from websockets' own request parser."""
    protocol = ServerProtocol()
    if data:
        protocol.receive_data(data)
    protocol.receive_eof()
    exc = protocol.handshake_exc
    assert exc is not None
    return logging.LogRecord(WEBSOCKETS_SERVER_LOGGER, logging.ERROR, __file__, 0, "opening handshake failed", (), (type(exc), exc, exc.__traceback__))


@pytest.mark.parametrize(
    ("data", "unused"),
    [(b"", True), (b"NOT A REQUEST\r\n\r\n", False), (b"GET / HTTP/1.1\r\n", False), (b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", None)],
)
def test_only_a_connection_closed_before_any_byte_counts_as_unused(data: bytes, unused: bool | None) -> None:
    if unused is None:  # a whole request: no handshake error at all
        protocol = ServerProtocol()
        protocol.receive_data(data)
        assert protocol.handshake_exc is None
        return
    assert is_unused_connection(_handshake_record(data)) is unused


CHILD = """
import socket, sys, time
sys.path.insert(0, {repo!r})
from addb_viewer.app.access import start_viser
server = start_viser("127.0.0.1", 0, token=None, verbose=False)
with socket.create_connection(("127.0.0.1", server.get_port()), timeout=10):
    pass  # a spare connection closed unused, before any request
time.sleep(1.0)
server.stop()
print("stopped", flush=True)
"""


def test_a_fresh_server_logs_nothing_for_an_unused_connection() -> None:
    r = subprocess.run([sys.executable, "-c", CHILD.format(repo=str(REPO))], capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0 and "stopped" in r.stdout, r.stderr
    assert "opening handshake failed" not in r.stderr, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
