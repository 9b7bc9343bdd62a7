"""The UI's gate on a real viser server, with a raw websocket client: a connection whose
Origin is not the page's own, or that does not present the token, is refused in its
opening handshake (HTTP 403) and is sent nothing; one with both gets the scene. (Real
Chromium, a page from another origin: tests/test_browser_origin.py.)"""

from __future__ import annotations

import pytest
import viser
from browser_helpers import free_port
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from web.access import (Access, make_token, page_origins, page_url, presented_token,
                        require_access)

TOKEN = "s3cret-token-for-the-test"


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    server.access = require_access(server, TOKEN, "127.0.0.1")
    server.scene.add_frame("/something")
    yield server
    server.stop()


def first_message(server, path: str, origin: str | None) -> bytes | None:
    """What the server sends first to a websocket at ``path`` with the ``Origin`` header
    ``origin`` (None: none sent); None when it is refused or closed first."""
    url = f"ws://127.0.0.1:{server.get_port()}{path}"
    try:
        with connect(url, origin=origin, subprotocols=[f"viser-v{viser.__version__}"],
                     open_timeout=30) as ws:
            try:
                return ws.recv(timeout=30)
            except ConnectionClosed:
                return None
    except InvalidStatus as refused:
        assert refused.response.status_code == 403
        return None


def own(server) -> str:
    return f"http://127.0.0.1:{server.get_port()}"


@pytest.mark.parametrize("path", ["/", "/?token=", "/?token=s3cret", f"/?token={TOKEN}x",
                                  f"/?token={TOKEN}&token={TOKEN}", f"/{TOKEN}"])
def test_a_page_without_the_token_gets_nothing(server, path):
    assert first_message(server, path, own(server)) is None
    assert server.access.refused == 1


@pytest.mark.parametrize("origin", ["http://evil.example", "http://evil.example:{port}",
                                    "http://127.0.0.1:{other}", "http://localhost:{other}",
                                    "https://127.0.0.1:{port}", "null", "", None,
                                    "http://127.0.0.1:{port}.evil.example"])
def test_a_foreign_origin_gets_nothing_even_with_the_token(server, origin):
    if origin is not None:
        origin = origin.format(port=server.get_port(), other=server.get_port() + 1)
    assert first_message(server, f"/?token={TOKEN}", origin) is None
    assert server.access.refused == 1


@pytest.mark.parametrize("name", ["127.0.0.1", "localhost", "LOCALHOST"])
def test_the_page_s_own_origin_with_the_token_gets_the_scene(server, name):
    assert first_message(server, f"/?token={TOKEN}", f"http://{name}:{server.get_port()}")
    assert server.access.refused == 0


def test_beyond_loopback_the_origin_must_be_the_host_the_page_came_from():
    access = Access(TOKEN, page_origins("0.0.0.0", 8080))
    path = f"/?token={TOKEN}"
    assert access.refusal(path, {"Host": "robot-pc:8080", "Origin": "http://robot-pc:8080"}) == ""
    assert "Origin" in access.refusal(path, {"Host": "robot-pc:8080",
                                             "Origin": "http://evil.example"})
    assert "token" in access.refusal("/", {"Host": "robot-pc:8080",
                                           "Origin": "http://robot-pc:8080"})
    assert page_origins("127.0.0.1", 8080) == {"http://127.0.0.1:8080", "http://localhost:8080",
                                               "http://[::1]:8080"}


def test_the_printed_address_carries_the_token_where_the_page_sends_it():
    url = page_url("192.168.1.5", 8080, TOKEN)
    assert url == f"http://192.168.1.5:8080/?websocket=ws://192.168.1.5:8080/?token={TOKEN}"
    assert presented_token(url.split("websocket=ws://192.168.1.5:8080")[1]) == TOKEN
    assert page_url("::1", 8080) == "http://[::1]:8080/"
    assert len(make_token("auto")) >= 16 and make_token("auto") != make_token("auto")
    with pytest.raises(ValueError, match="token must be at least 16"):
        make_token("a b c d e f g h i j")


def test_without_the_handshake_hook_the_connect_check_still_closes_a_foreign_page(monkeypatch):
    """The second line (viser's internals changed): the connection opens, and is closed
    before it is sent anything."""
    import web.access

    monkeypatch.setattr(web.access, "_handshake_server", lambda server: None)
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        server.access = require_access(server, TOKEN, "127.0.0.1")
        server.scene.add_frame("/something")
        assert first_message(server, f"/?token={TOKEN}", "http://evil.example") is None
        assert first_message(server, "/", own(server)) is None
        assert server.access.refused == 2
        assert first_message(server, f"/?token={TOKEN}", own(server))
    finally:
        server.stop()
