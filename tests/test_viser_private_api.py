"""The parts of viser that are not its public API and that the UI's token check
(web/access.py, :func:`web.access.require_access`) and the pacing of a page's messages
(web/pacing.py) read, on the installed viser: if an
update renames or reshapes one, this file fails naming it (pyproject pins viser to the
minor series they were read on; moving the pin means running this file first).

Read: ``ViserServer._websock_server``; on it ``_client_connect_cb`` (a list of async
callbacks the gate puts itself first in) and ``_live_connections`` (client id -> the
websocket, whose ``request`` has the ``path`` and ``headers`` of the handshake); the
websockets server found by its port, whose ``process_request`` the gate wraps; viser
reading a connection's messages through the websocket's ``recv`` attribute, looked up
after the connect callbacks ran (the pacing replaces it there).
"""

from __future__ import annotations

import threading

import pytest
import viser
import websockets.asyncio.server
from browser_helpers import free_port
from websockets.sync.client import connect

from web.access import _handshake_server


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield server
    server.stop()


def test_the_websocket_server_behind_viser_has_the_members_the_gate_reads(server):
    websock_server = getattr(server, "_websock_server", None)
    assert websock_server is not None, "viser.ViserServer._websock_server is gone"
    callbacks = getattr(websock_server, "_client_connect_cb", None)
    assert isinstance(callbacks, list), f"_client_connect_cb is {type(callbacks).__name__}, not a list"
    live = getattr(websock_server, "_live_connections", None)
    assert isinstance(live, dict), f"_live_connections is {type(live).__name__}, not a dict"
    handshake = _handshake_server(server)
    assert isinstance(handshake, websockets.asyncio.server.Server), \
        "no websockets server listens on viser's port"
    assert "process_request" in vars(handshake), "the handshake server has no process_request"


def test_a_connect_callback_first_in_the_list_sees_the_request_of_the_new_connection(server):
    """What the gate's second line does: a callback put first in ``_client_connect_cb``
    is called with the connection, whose client id finds the websocket and its request."""
    websock_server = server._websock_server
    seen: dict[str, object] = {}
    called = threading.Event()

    async def check(connection) -> None:
        websocket = websock_server._live_connections.get(connection.client_id)
        seen["path"] = websocket.request.path
        seen["has_headers"] = hasattr(websocket.request, "headers")
        called.set()

    websock_server._client_connect_cb.insert(0, check)
    url = f"ws://127.0.0.1:{server.get_port()}/?token=abc"
    with connect(url, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=30):
        assert called.wait(30), "the connect callback was not called"
    assert seen == {"path": "/?token=abc", "has_headers": True}


def test_viser_reads_a_connection_s_messages_through_its_recv_looked_up_after_connecting(server):
    """What the pacing does: a connect callback replaces the websocket's ``recv``; viser's
    reader then takes every message through it."""
    websock_server = server._websock_server
    taken: list[bytes] = []
    done = threading.Event()

    async def wrap(connection) -> None:
        websocket = websock_server._live_connections.get(connection.client_id)
        receive = websocket.recv

        async def recv(decode=None):
            message = await receive()
            taken.append(message)
            done.set()
            return message
        websocket.recv = recv

    websock_server._client_connect_cb.insert(0, wrap)
    url = f"ws://127.0.0.1:{server.get_port()}/"
    with connect(url, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=30) as ws:
        ws.send(b"\x81\xa4type\xa9NotViser!")  # read (then refused by viser's decoder)
        assert done.wait(30), "viser did not read through the replaced recv"
    assert taken == [b"\x81\xa4type\xa9NotViser!"]
