"""The token gate on a real viser server, with a raw websocket client: a connection that
does not present the token is closed before it is sent anything; one that does gets the
scene. (A real browser opening the printed address: tests/test_browser_files.py.)"""

from __future__ import annotations

import pytest
import viser
from browser_helpers import free_port
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from web.access import REFUSED, make_token, page_url, presented_token, require_token

TOKEN = "s3cret-token-for-the-test"


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    require_token(server, TOKEN)
    server.scene.add_frame("/something")
    yield server
    server.stop()


def first_message(server, path: str) -> bytes | None:
    """What the server sends first to a websocket at ``path`` (None: closed first)."""
    url = f"ws://127.0.0.1:{server.get_port()}{path}"
    with connect(url, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=30) as ws:
        try:
            return ws.recv(timeout=30)
        except ConnectionClosed as closed:
            assert closed.rcvd is not None and closed.rcvd.code == REFUSED
            return None


@pytest.mark.parametrize("path", ["/", "/?token=", "/?token=s3cret", f"/?token={TOKEN}x",
                                  f"/?token={TOKEN}&token={TOKEN}", f"/{TOKEN}"])
def test_a_page_without_the_token_gets_nothing(server, path):
    assert first_message(server, path) is None


def test_a_page_with_the_token_gets_the_scene(server):
    assert first_message(server, f"/?token={TOKEN}")


def test_the_printed_address_carries_the_token_where_the_page_sends_it():
    url = page_url("192.168.1.5", 8080, TOKEN)
    assert url == f"http://192.168.1.5:8080/?websocket=ws://192.168.1.5:8080/?token={TOKEN}"
    assert presented_token(url.split("websocket=ws://192.168.1.5:8080")[1]) == TOKEN
    assert page_url("::1", 8080) == "http://[::1]:8080/"
    assert len(make_token("auto")) >= 16 and make_token("auto") != make_token("auto")
    with pytest.raises(ValueError, match="token must be at least 16"):
        make_token("a b c d e f g h i j")
