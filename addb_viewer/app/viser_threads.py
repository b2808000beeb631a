"""Make viser's message buffers safe to push to from the review app's threads (no app state).

The review app changes the page from many threads: viser runs each page's handlers in a
thread pool, playback runs in its own thread, jobs report from theirs. viser 1.1.1's
``AsyncMessageBuffer.push`` wakes the connection's sender by calling
``asyncio.Event.set()`` directly in the pushing thread (then again, correctly, through
``loop.call_soon_threadsafe``). ``asyncio.Event`` is not thread-safe: ``set()`` iterates
the event's waiters while the event loop's thread may be adding or removing one, and
then the push raises ``RuntimeError: deque mutated during iteration`` in the app's
thread (seen once in the test suite, in a camera update of ``page_cameras``). The message
itself was already stored, so nothing is lost but the handler that pushed it stops half
way.

:func:`make_pushes_thread_safe` gives every buffer of a server an event whose ``set()``
from another thread is handed to the event loop (``call_soon_threadsafe``), which is
what the direct call was for: the loop's sender is woken a moment later, as it is by
viser's own threadsafe call. It reaches into viser's private ``_websock_server``
(viser is pinned to one version in pyproject.toml) and fails loudly if that changes.
"""

from __future__ import annotations

import asyncio
from typing import Any


class LoopSafeEvent(asyncio.Event):
    """An ``asyncio.Event`` of one event loop whose :meth:`set` may be called from any thread.

    Parameters
    ----------
    loop
        The event loop whose coroutines wait on the event.

    In the loop's own thread (or while the loop does not run) ``set()`` is
    ``asyncio.Event.set``; from another thread it is scheduled in the loop
    (``call_soon_threadsafe``), so the waiters are only ever touched by the loop's thread.
    A set from another thread while the event is set, or while a set is already scheduled,
    schedules nothing more (``asyncio.Event.set`` would do nothing then either): a scene
    update pushes dozens of messages, and waking the loop for each one slowed it (the
    viewer benchmark's ``scene.show`` median went from 2.3 to 3.8 ms). A loop closed
    meanwhile has no waiter left to wake: the call does nothing.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._home = loop
        self._scheduled = False

    def set(self) -> None:
        """Set the event now (in the loop's thread) or as soon as the loop runs (elsewhere)."""
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._home or not self._home.is_running():
            super().set()
            return
        if self.is_set() or self._scheduled:
            return
        self._scheduled = True
        try:
            self._home.call_soon_threadsafe(self._set_in_loop)
        except RuntimeError:  # the loop closed meanwhile (server stopping)
            self._scheduled = False

    def _set_in_loop(self) -> None:
        self._scheduled = False
        super().set()


def _swap_event(buffer: Any) -> None:
    """Give ``buffer`` (a viser ``AsyncMessageBuffer``) a :class:`LoopSafeEvent`, set if
    its old event was."""
    old = buffer.message_event
    if isinstance(old, LoopSafeEvent):
        return
    new = LoopSafeEvent(buffer.event_loop)
    if old.is_set():
        new.set()
    buffer.message_event = new


def make_pushes_thread_safe(server: Any) -> None:
    """Give the broadcast buffer of ``server`` (a started ``viser.ViserServer``) and the
    buffer of every page that connects to it a :class:`LoopSafeEvent`.

    Call it right after the server starts, before any page connects: a page's buffer is
    changed in the connection callback, which viser runs in its event loop before the
    page's sender starts waiting.

    Raises
    ------
    RuntimeError
        viser no longer has the private ``_websock_server`` with a broadcast buffer and
        connection callbacks this relies on (a viser upgrade; see the module docstring).
    """
    ws = getattr(server, "_websock_server", None)
    buffer = getattr(ws, "_broadcast_buffer", None)
    if buffer is None or not hasattr(buffer, "message_event") or not hasattr(ws, "on_client_connect"):
        raise RuntimeError(
            "viser's private _websock_server._broadcast_buffer.message_event is gone (viser was upgraded?): "
            "addb_viewer.app.viser_threads cannot make pushes from the app's threads safe"
        )
    loop = buffer.event_loop
    # the loop thread already waits on the broadcast event: swap it in the loop's thread
    done = asyncio.run_coroutine_threadsafe(_swap_in_loop(buffer), loop)
    done.result(timeout=10)
    ws.on_client_connect(lambda connection: _swap_event(connection.get_message_buffer()))


async def _swap_in_loop(buffer: Any) -> None:
    old = buffer.message_event
    _swap_event(buffer)
    old.set()  # a sender already waiting on the old event wakes, then waits on the new one
