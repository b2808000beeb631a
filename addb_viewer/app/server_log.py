"""Quiet the review server's log about connections that close before saying anything.

Browsers open spare TCP connections to a page's host ahead of need (Chromium's
preconnects) and close them unused, for example when a tab reloads or the browser exits.
The websockets server under viser then logs ``opening handshake failed`` at ERROR level,
with a three-part traceback ending in ``InvalidMessage: did not receive a valid HTTP
request`` caused by ``EOFError`` (zero bytes received). Nothing failed: a reviewer seeing
that traceback on the terminal would think the app broke. :func:`quiet_unused_connections`
drops exactly those records; every other handshake failure (a malformed request, a refused
upgrade, a timeout after a partial request) is still logged as before.
"""

from __future__ import annotations

import logging

#: The logger websockets' server side writes to.
WEBSOCKETS_SERVER_LOGGER = "websockets.server"


def is_unused_connection(record: logging.LogRecord) -> bool:
    """True for websockets' ``opening handshake failed`` record of a connection that closed
    before sending any byte of a request (``InvalidMessage`` caused by ``EOFError`` whose
    message says 0 bytes were received)."""
    if record.getMessage() != "opening handshake failed" or not record.exc_info:
        return False
    exc = record.exc_info[1]
    if type(exc).__name__ != "InvalidMessage":
        return False
    cause = exc.__cause__
    while cause is not None:  # InvalidMessage <- EOFError (request line) <- EOFError (0 bytes)
        if isinstance(cause, EOFError) and "after 0 bytes" in str(cause):
            return True
        cause = cause.__cause__
    return False


class _DropUnusedConnections(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not is_unused_connection(record)


def quiet_unused_connections() -> None:
    """Install the filter on websockets' server logger (once per process)."""
    logger = logging.getLogger(WEBSOCKETS_SERVER_LOGGER)
    if not any(isinstance(f, _DropUnusedConnections) for f in logger.filters):
        logger.addFilter(_DropUnusedConnections())
