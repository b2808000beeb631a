"""An access token for the review app when it listens beyond this machine.

``addb view --host 0.0.0.0`` lets a team review on a lab server. Anyone who can reach the
port could then read the subject and edit its review record, so, as Jupyter does, the app
then requires a random token (:func:`new_token`): the printed address carries it
(``http://HOST:PORT/?token=...``), and the first page load with it sets a cookie
(``addb_token_<port>``, HttpOnly, SameSite=Strict) that the browser sends with every later
request, the websocket handshake included. A request, HTTP or websocket, with neither the
token nor the cookie is answered 403 and logged on the terminal (method, path without its
query, client address; never a token). On a loopback address (127.0.0.1, ::1,
localhost) nothing changes.

How it hooks into viser 1.1.1: viser serves its page and its websocket on one port with
``websockets.asyncio.server.serve(..., process_request=viser_http_server)``, the hook
websockets provides to answer or refuse a request before the handshake. viser offers no
option to pass our own, so :func:`start_viser` wraps ``serve`` while (and only while) the
``ViserServer`` binds its port, and wraps the ``process_request`` given to it with the
gate; the wrapper passes every other call through unchanged. If a future viser stops
calling ``serve`` this way, the gate would not be installed: :func:`start_viser` then stops
the server and raises rather than serve without the token.
"""

from __future__ import annotations

import contextlib
import http
import http.cookies
import io
import ipaddress
import secrets
import sys
import threading
import time
from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qs, urlsplit

from solver.errors import AddbError

#: Query parameter of the address that carries the token.
TOKEN_PARAM = "token"

#: Cookie carrying the token after the first page load (the port is appended: cookies
#: are shared by all ports of a host, and two servers must not overwrite each other's).
COOKIE_PREFIX = "addb_token_"


class AccessSetupError(AddbError):
    """The access token could not be enforced (viser no longer serves as expected)."""


def is_loopback(host: str) -> bool:
    """True when ``host`` is reachable from this machine only (127.0.0.0/8, ::1, localhost).

    The wildcard addresses (``0.0.0.0``, ``::``, ``""``) and every other address or host
    name are not loopback.
    """
    h = host.strip().strip("[]").lower()
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


def new_token() -> str:
    """A fresh random access token (32 bytes from :mod:`secrets`, URL-safe text)."""
    return secrets.token_urlsafe(32)


class AccessGate:
    """Answers whether a request carries the token, and refuses it otherwise.

    Parameters
    ----------
    token
        The access token.
    log
        Called with one line per refused request (default: printed to stderr).
    """

    def __init__(self, token: str, *, log: Callable[[str], None] | None = None) -> None:
        if not token:
            raise ValueError("the access token must not be empty")
        self.token = token
        self.refused = 0
        self._log = log or (lambda line: print(line, file=sys.stderr, flush=True))
        self._lock = threading.Lock()

    def cookie_name(self, port: int) -> str:
        """Name of the cookie for a server on ``port``."""
        return f"{COOKIE_PREFIX}{port}"

    def check(self, path: str, cookie_headers: list[str], port: int) -> tuple[bool, bool]:
        """``(authorized, by_query)`` for a request target ``path`` (with its query) and
        its ``Cookie`` header values, on a server listening on ``port``."""
        query = parse_qs(urlsplit(path).query)
        for value in query.get(TOKEN_PARAM, []):
            if secrets.compare_digest(value.encode(), self.token.encode()):
                return True, True
        name = self.cookie_name(port)
        for header in cookie_headers:
            jar = http.cookies.SimpleCookie()
            try:
                jar.load(header)
            except http.cookies.CookieError:
                continue
            if name in jar and secrets.compare_digest(jar[name].value.encode(), self.token.encode()):
                return True, False
        return False, False

    def wrap(self, inner: Callable[..., Any] | None) -> Callable[..., Any]:
        """A websockets ``process_request`` that refuses requests without the token and
        otherwise calls ``inner`` (viser's page server), adding the cookie to a page
        served to a request that carried the token in its query."""

        def process_request(connection: Any, request: Any) -> Any:
            port = int(connection.local_address[1])
            ok, by_query = self.check(request.path, request.headers.get_all("Cookie"), port)
            upgrade = request.headers.get("Upgrade", "").lower() == "websocket"
            if not ok:
                with self._lock:
                    self.refused += 1
                peer = connection.remote_address[0] if connection.remote_address else "?"
                kind = "websocket" if upgrade else "HTTP GET"
                self._log(
                    f"addb view: {time.strftime('%H:%M:%S')} refused {kind} {urlsplit(request.path).path} "
                    f"from {peer}: no valid access token"
                )
                return connection.respond(
                    http.HTTPStatus.FORBIDDEN,
                    "This addb review server needs its access token: open the address that "
                    "`addb view` printed (http://HOST:PORT/?token=...).\n",
                )
            response = inner(connection, request) if inner is not None else None
            if response is not None and by_query:
                response.headers["Set-Cookie"] = (
                    f"{self.cookie_name(port)}={self.token}; Path=/; HttpOnly; SameSite=Strict"
                )
            return response

        return process_request


_install_lock = threading.Lock()


def start_viser(host: str, port: int, *, token: str | None, **kwargs: Any) -> Any:
    """A started ``viser.ViserServer(host, port, **kwargs)``, gated by ``token``.

    Parameters
    ----------
    host, port
        Where to listen (see ``viser.ViserServer``).
    token
        The access token every request must carry (query or cookie); None: no gate.
    **kwargs
        Passed to ``viser.ViserServer``.

    Connections a browser opens and closes unused are not logged as failed handshakes
    (:mod:`addb_viewer.app.server_log`); the app's threads may push to the pages
    (:mod:`addb_viewer.app.viser_threads`).

    Returns
    -------
    viser.ViserServer
        The server, with ``server.addb_access_gate`` set to the :class:`AccessGate` (None
        without a token).

    Raises
    ------
    AccessSetupError
        A token was asked for but viser did not start its server through
        ``websockets.asyncio.server.serve`` with a ``process_request`` hook (the server
        is stopped again).
    """
    import viser
    import websockets.asyncio.server as ws_server

    from addb_viewer.app.server_log import quiet_unused_connections
    from addb_viewer.app.viser_threads import make_pushes_thread_safe

    quiet_unused_connections()
    if token is None:
        server = viser.ViserServer(host=host, port=port, **kwargs)
        make_pushes_thread_safe(server)
        server.addb_access_gate = None
        return server
    gate = AccessGate(token)
    installed: list[bool] = []
    with _install_lock:
        original = ws_server.serve
        caller = threading.get_ident()

        def serve(*args: Any, **kw: Any) -> Any:
            # viser calls this from its server thread while ViserServer() (in ``caller``)
            # waits for the port to be bound; other callers pass through unchanged.
            if "process_request" in kw and threading.get_ident() != caller:
                kw["process_request"] = gate.wrap(kw["process_request"])
                installed.append(True)
            return original(*args, **kw)

        ws_server.serve = serve
        try:
            # viser prints its own address box, without the token (a wildcard host shown as
            # localhost): a reviewer given that address is refused; the caller prints the
            # address with the token instead
            with contextlib.redirect_stdout(io.StringIO()):
                server = viser.ViserServer(host=host, port=port, **kwargs)
        finally:
            ws_server.serve = original
    if not installed:
        server.stop()
        raise AccessSetupError(
            f"viser {viser.__version__} did not start its server through websockets' serve(process_request=...); "
            "the access token cannot be enforced, so the server was not started on a non-loopback address"
        )
    make_pushes_thread_safe(server)
    server.addb_access_gate = gate
    return server
