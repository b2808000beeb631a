"""Pushes to the page from the app's threads never touch asyncio's waiters outside the
event loop (:mod:`addb_viewer.app.viser_threads`): the fix of a ``RuntimeError: deque
mutated during iteration`` that viser 1.1.1's ``AsyncMessageBuffer.push`` raised once in
a page-camera update."""

from __future__ import annotations

import asyncio
import threading

import pytest
import viser
from viewer_support import ProtocolClient, wait_for

from addb_viewer.app.viser_threads import LoopSafeEvent, make_pushes_thread_safe


def test_a_set_from_another_thread_runs_in_the_loop() -> None:
    """While the loop is busy, ``set()`` from this thread changes nothing (a plain
    ``asyncio.Event`` would wake its waiter here, in the wrong thread); once the loop runs
    again the waiter wakes. Sets before the loop gets to the first schedule one wake-up."""
    loop = asyncio.new_event_loop()
    runner = threading.Thread(target=loop.run_forever, daemon=True)
    runner.start()
    wakes: list[int] = []

    class Counted(LoopSafeEvent):
        def _set_in_loop(self) -> None:
            wakes.append(1)
            super()._set_in_loop()

    try:
        event = Counted(loop)
        waiter = asyncio.run_coroutine_threadsafe(event.wait(), loop)
        hold, holding = threading.Event(), threading.Event()

        def busy() -> None:
            holding.set()
            hold.wait(30)

        loop.call_soon_threadsafe(busy)
        assert holding.wait(30)
        for _ in range(5):
            event.set()
        assert not event.is_set() and not waiter.done()
        plain = asyncio.Event()
        plain.set()  # the behaviour the class replaces: set at once in the calling thread
        assert plain.is_set()
        hold.set()
        assert waiter.result(timeout=30) is True
        assert event.is_set() and wakes == [1]
        event.set()  # already set: nothing scheduled
        asyncio.run_coroutine_threadsafe(asyncio.sleep(0), loop).result(timeout=30)
        assert wakes == [1]
    finally:
        loop.call_soon_threadsafe(loop.stop)
        runner.join(30)
        loop.close()
    event.set()  # a closed loop: nothing to wake, no error
    closed = LoopSafeEvent(loop)
    closed.set()
    assert closed.is_set()  # not running: set in place


def test_every_buffer_of_a_server_gets_the_event_and_pushes_arrive() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    client = None
    try:
        make_pushes_thread_safe(server)
        ws = server._websock_server
        assert isinstance(ws._broadcast_buffer.message_event, LoopSafeEvent)
        client = ProtocolClient(server.get_port())
        (page,) = wait_for(lambda: list(server.get_clients().values()), what="the page")
        assert isinstance(page._websock_connection.get_message_buffer().message_event, LoopSafeEvent)
        number = server.gui.add_number("x", 0.0)
        before = client.received
        pushes = [threading.Thread(target=lambda k=k: setattr(number, "value", float(k))) for k in range(8)]
        for t in pushes:
            t.start()
        for t in pushes:
            t.join(30)
        wait_for(lambda: client.received > before, what="the pushes from other threads")
    finally:
        if client is not None:
            client.close()
        server.stop()


def test_the_app_server_has_it(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    assert isinstance(app.server._websock_server._broadcast_buffer.message_event, LoopSafeEvent)


def test_a_viser_without_the_private_buffer_is_refused() -> None:
    with pytest.raises(RuntimeError, match="viser's private _websock_server"):
        make_pushes_thread_safe(object())
