"""Who may reach the UI: the address it binds, the token and the Origin a page must present.

The UI moves a robot and reads and writes files in two folders (docs/design.md section
5.3). By default it binds the loopback interface only. Every browser connection (a
websocket) is checked during its opening handshake, before viser sees it
(:func:`require_access`), and refused with HTTP 403 unless

* its **Origin** is the page's own: ``http://127.0.0.1:PORT``, ``http://localhost:PORT``
  or ``http://[::1]:PORT`` for a loopback server, else ``http://`` and the Host it asked
  for: a page from any other site the operator has open (cross-site websocket
  hijacking) gets nothing;
* and, when the server has a **token**, its URL carries it, ``/?token=TOKEN``.

``teleop web`` always has a token, drawn per launch unless ``--token`` gives one (as
Jupyter does); beyond loopback it must be given. The page is opened at
:func:`page_url`, which tells viser's page to connect its websocket there.

The token travels in clear text over HTTP: it keeps out other users of a network you
trust, not an eavesdropper; across an untrusted network use an SSH tunnel to a loopback
server instead (with the same port on both ends: the Origin names it).
"""

from __future__ import annotations

import errno
import gc
import hmac
import http
import ipaddress
import re
import secrets
import socket
import threading
from urllib.parse import parse_qs, urlsplit

import viser
import websockets.asyncio.server

#: seconds a host name may take to resolve before it is refused
RESOLVE_TIMEOUT = 5.0
#: the shortest token accepted (characters); ``--token auto`` makes a 32-character one
MIN_TOKEN = 16
#: a token is URL-safe text (it goes into the page's address unescaped)
TOKEN_PATTERN = re.compile(r"[A-Za-z0-9_\-.~]+")
_HOSTNAME = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*\.?")
#: the websocket close code for a refused page (RFC 6455: policy violation)
REFUSED = 1008


def check_port(port: object) -> int:
    """``port`` as a TCP port number 1-65535, else ``ValueError`` naming it."""
    if isinstance(port, bool) or not isinstance(port, int) and not (
            isinstance(port, str) and port.strip().isdigit()):
        raise ValueError(f"port must be a whole number from 1 to 65535, got {port!r}")
    number = int(port)
    if not 1 <= number <= 65535:
        raise ValueError(f"port must be from 1 to 65535, got {number}")
    return number


def resolve_host(host: object) -> list[str]:
    """The IP addresses ``host`` (an IP address or a host name) stands for; ``ValueError``
    when it is neither, or does not resolve within :data:`RESOLVE_TIMEOUT` s."""
    if not isinstance(host, str) or not host.strip():
        raise ValueError(f"host must be an IP address or a host name, got {host!r}")
    host = host.strip()
    try:
        return [str(ipaddress.ip_address(host))]
    except ValueError:
        pass
    if len(host) > 253 or not _HOSTNAME.fullmatch(host):
        raise ValueError(f"host {host!r} is not an IP address or a host name")
    found: list[str] = []
    failure: list[str] = []

    def lookup() -> None:
        try:
            found.extend(dict.fromkeys(info[4][0] for info in socket.getaddrinfo(
                host, None, type=socket.SOCK_STREAM)))
        except OSError as error:
            failure.append(str(error))

    thread = threading.Thread(target=lookup, name="resolve", daemon=True)
    thread.start()
    thread.join(RESOLVE_TIMEOUT)
    if thread.is_alive():
        raise ValueError(f"host {host!r} did not resolve within {RESOLVE_TIMEOUT:g} s")
    if failure or not found:
        raise ValueError(f"host {host!r} does not resolve to an address")
    return found


def is_loopback(addresses: list[str]) -> bool:
    """Whether every address is a loopback one (only this machine can connect)."""
    return all(ipaddress.ip_address(address.split("%")[0]).is_loopback for address in addresses)


def check_bind(addresses: list[str], port: int) -> None:
    """``ValueError`` unless this machine can listen on ``port`` of the first address
    (a port in use is left to viser, which then takes the next free one)."""
    address = addresses[0]
    family = socket.AF_INET6 if ":" in address else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((address, port))
        except OSError as error:
            if error.errno == errno.EADDRINUSE and port < 65535:
                return
            raise ValueError(f"cannot listen on {address} port {port}: "
                             f"{error.strerror or error}") from None


def make_token(token: str) -> str:
    """``token`` checked (URL-safe, at least :data:`MIN_TOKEN` characters); ``"auto"``
    makes a random one."""
    if token == "auto":
        return secrets.token_urlsafe(24)
    if not TOKEN_PATTERN.fullmatch(token) or len(token) < MIN_TOKEN:
        raise ValueError(f"token must be at least {MIN_TOKEN} characters of A-Z a-z 0-9 _ - . ~ "
                         "(or 'auto' for a random one)")
    return token


def page_url(host: str, port: int, token: str | None = None) -> str:
    """The address a browser opens: with a token, viser's page is told (its ``websocket``
    parameter) to connect with it."""
    name = f"[{host}]" if ":" in host else host
    if token is None:
        return f"http://{name}:{port}/"
    return f"http://{name}:{port}/?websocket=ws://{name}:{port}/?token={token}"


def presented_token(path: str) -> str:
    """The token in a websocket request path (``/?token=...``), ``""`` when none."""
    values = parse_qs(urlsplit(path).query).get("token", [])
    return values[0] if len(values) == 1 else ""


def page_origins(host: str, port: int) -> frozenset[str] | None:
    """The Origins a page of a server bound to ``host:port`` may have: the loopback names
    for a loopback server, None (the Host the browser asked for) for any other."""
    try:
        loopback = is_loopback([host]) if host != "localhost" else True
    except ValueError:  # a host name
        loopback = False
    if not loopback:
        return None
    return frozenset(f"http://{name}:{port}" for name in ("127.0.0.1", "localhost", "[::1]"))


class Access:
    """The checks every websocket of one server passes: its Origin, and the token.

    token : what the URL must carry (None: no token asked).
    origins : the Origins a page may have (None: ``http://`` and the request's Host).
    """

    def __init__(self, token: str | None, origins: frozenset[str] | None) -> None:
        self.token = token
        self.origins = origins
        #: websockets refused so far
        self.refused = 0

    def refusal(self, path: str, headers) -> str:
        """Why a websocket request (its path and headers) is refused, "" when it is not."""
        origin = (headers.get("Origin") or "").strip().lower()
        if not origin:
            return "no Origin: only the UI's own page may connect"
        own = self.origins if self.origins is not None else {
            f"http://{(headers.get('Host') or '').strip().lower()}"}
        if origin not in own:
            return f"Origin {origin[:100]} is not this UI's page"
        if self.token is not None and not hmac.compare_digest(
                presented_token(path).encode(), self.token.encode()):
            return "this UI needs its token: open the address `teleop web` printed"
        return ""


def _handshake_server(server: viser.ViserServer):
    """The websockets server behind ``server`` (which viser does not expose), found by
    its listening port; None if it cannot be found."""
    port = server.get_port()
    for candidate in gc.get_objects():
        if isinstance(candidate, websockets.asyncio.server.Server) and \
                candidate.server is not None and any(
                    sock.getsockname()[1] == port for sock in candidate.server.sockets):
            return candidate
    return None


def require_access(server: viser.ViserServer, token: str | None, host: str) -> Access:
    """Refuse every websocket of ``server`` (bound to ``host``) whose Origin is not the
    page's own or whose URL does not carry ``token`` (None: no token asked).

    The check runs in the opening handshake (an HTTP 403: the connection never reaches
    viser, which is sent and reads nothing). As a second line, in case the handshake
    cannot be hooked, the same check runs first among the websocket server's connect
    callbacks, before viser starts a connection's senders, and closes it.
    """
    access = Access(token, page_origins(host, server.get_port()))
    websocket_server = server._websock_server
    handshake = _handshake_server(server)
    if handshake is not None:
        serve_page = handshake.process_request

        def gate(connection, request):
            if (request.headers.get("Upgrade") or "").lower() == "websocket":
                reason = access.refusal(request.path, request.headers)
                if reason:
                    access.refused += 1
                    return connection.respond(http.HTTPStatus.FORBIDDEN, reason + "\n")
            return None if serve_page is None else serve_page(connection, request)

        handshake.process_request = gate

    async def check(connection) -> None:
        websocket = websocket_server._live_connections.get(connection.client_id)
        if websocket is None:
            return
        request = websocket.request
        reason = access.refusal(request.path, request.headers) if request else "no request"
        if reason:
            access.refused += 1
            await websocket.close(REFUSED, reason[:120])

    websocket_server._client_connect_cb.insert(0, check)
    return access
