"""Who may reach the UI: the address it binds, and the token a page must present.

The UI moves a robot and reads and writes files in two folders (docs/design.md section
5.3). By default it binds the loopback interface only. Bound to anything else it needs a
**token** (``teleop web --host ADDRESS --token TOKEN``): every browser connection
(a websocket) must present it in its URL, ``/?token=TOKEN``, or it is closed before it
receives anything (no scene, no panels) and before any of its messages is read. The page
is opened at :func:`page_url`, which tells viser's page to connect its websocket there.

The token travels in clear text over HTTP: it keeps out other users of a network you
trust, not an eavesdropper; across an untrusted network use an SSH tunnel to a loopback
server instead.
"""

from __future__ import annotations

import errno
import hmac
import ipaddress
import re
import secrets
import socket
import threading
from urllib.parse import parse_qs, urlsplit

import viser

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


def require_token(server: viser.ViserServer, token: str) -> None:
    """Close every websocket of ``server`` whose URL does not carry ``token``, before it
    is sent anything or any of its messages is read.

    viser runs the websocket server's connect callbacks before it starts a connection's
    senders and reader; this one is registered on that server (viser's own
    ``on_client_connect`` fires only later, on the page's first camera message).
    """
    websocket_server = server._websock_server
    expected = token.encode()

    async def check(connection) -> None:
        websocket = websocket_server._live_connections.get(connection.client_id)
        if websocket is None:
            return
        presented = presented_token(websocket.request.path if websocket.request else "")
        if not hmac.compare_digest(presented.encode(), expected):
            await websocket.close(REFUSED, "this UI needs its token: open the address "
                                           "`teleop web` printed")

    websocket_server.on_client_connect(check)
