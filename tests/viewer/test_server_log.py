"""The review server does not log a browser's unused spare connections as failed handshakes
(:mod:`addb_viewer.app.server_log`), and still logs a real failed handshake.

Found by ``test_viewer_browser.py::test_review_in_the_browser`` on a fresh clone: Chromium
closed a preconnected socket without a request and the websockets server under viser
printed a three-part traceback on the app's terminal."""

from __future__ import annotations

import logging
import socket
import time

import pytest

from addb_viewer.app.access import start_viser
from addb_viewer.app.server_log import WEBSOCKETS_SERVER_LOGGER


def _connect_and_send(port: int, data: bytes) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        if data:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
            s.recv(1024)  # the server's answer or its close


def _handshake_failures(caplog: pytest.LogCaptureFixture, before: int, timeout: float = 5.0) -> list[logging.LogRecord]:
    """The "opening handshake failed" records after the first ``before`` records, once the
    server has had ``timeout`` seconds (or less, when one arrived) to log them."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = [r for r in caplog.records[before:] if r.getMessage() == "opening handshake failed"]
        if found:
            return found
        time.sleep(0.05)
    return []


def test_an_unused_connection_is_not_logged_and_a_bad_request_is(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger=WEBSOCKETS_SERVER_LOGGER)
    server = start_viser("127.0.0.1", 0, token=None, verbose=False)
    try:
        port = server.get_port()
        n = len(caplog.records)
        _connect_and_send(port, b"")  # a preconnect closed unused
        assert _handshake_failures(caplog, n, timeout=2.0) == []
        n = len(caplog.records)
        _connect_and_send(port, b"NOT A REQUEST\r\n\r\n")  # a malformed request: still logged
        failures = _handshake_failures(caplog, n)
        assert len(failures) == 1 and failures[0].levelno == logging.ERROR and failures[0].exc_info
    finally:
        server.stop()
