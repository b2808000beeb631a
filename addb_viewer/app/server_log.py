"""Quiet the review server's log about connections that close before saying anything.

Browsers open spare TCP connections to a page's host ahead of need (Chromium's
preconnects) and close them unused, for example when a tab reloads or the browser exits.
The websockets server under viser then logs ``opening handshake failed`` at ERROR level,
with a three-part traceback ending in ``InvalidMessage: did not receive a valid HTTP
request`` caused by ``EOFError`` (zero bytes received). Nothing failed: a reviewer seeing
that traceback on the terminal would think the app broke. :func:`quiet_unused_connections`
drops exactly those records and passes every other handshake failure (a malformed request,
a request cut off after its first line).

viser 1.1.1 has its own filter on that logger, dropping every ``opening handshake failed``
record, but installs it only when its server answers its first HTTP request; a spare
connection that closes before that was logged (seen in ``test_viewer_browser.py`` on a
fresh clone).
"""

from __future__ import annotations

import logging

#: The logger websockets' server side writes to.
WEBSOCKETS_SERVER_LOGGER = "websockets.server"


def is_unused_connection(record: logging.LogRecord) -> bool:
    """True for websockets' ``opening handshake failed`` record of a connection that closed
    before sending any byte of a request: ``InvalidMessage`` caused by ``EOFError`` while
    reading the request line, caused by ``EOFError`` after 0 bytes (websockets 16's
    messages; if they change, the record is kept, not dropped)."""
    if record.getMessage() != "opening handshake failed" or not record.exc_info:
        return False
    exc = record.exc_info[1]
    if type(exc).__name__ != "InvalidMessage":
        return False
    line = exc.__cause__
    if not isinstance(line, EOFError) or "request line" not in str(line):
        return False
    stream = line.__cause__
    return isinstance(stream, EOFError) and "after 0 bytes" in str(stream)


class _DropUnusedConnections(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not is_unused_connection(record)


def quiet_unused_connections() -> None:
    """Install the filter on websockets' server logger (once per process)."""
    logger = logging.getLogger(WEBSOCKETS_SERVER_LOGGER)
    if not any(isinstance(f, _DropUnusedConnections) for f in logger.filters):
        logger.addFilter(_DropUnusedConnections())
