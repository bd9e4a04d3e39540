"""The address of an existing Dask scheduler: parsed and checked before any connection, then probed with a
bounded handshake before Dask's client is made.

An address is ``tcp://HOST:PORT`` or ``tls://HOST:PORT`` (``HOST:PORT`` means tcp, as in Dask): HOST a DNS
name (RFC 1123 labels), an IPv4 address or an IPv6 address in brackets; PORT 1-65535, written in ASCII digits.
Other schemes are refused: ``inproc://`` exists only inside one Python process (a command cannot reach
another's), and clothlab's clusters are reached over TCP (docs/parallel.md).

Why a probe: Dask's client reads the first 8 bytes a server sends as the length of a message and allocates
that many bytes, so any other service answering on the port (an HTTP server, a database) becomes an
allocation of up to 2**64 bytes or a hang.  A Dask server speaks first: on accept it sends its handshake, a
small message of frames (``distributed.comm.tcp``: a uint64 total length, then a uint64 frame count, the
frame lengths and the frames; the first frame is a msgpack map with the key ``pickle-protocol``).  The
probe connects with a timeout, reads at most :data:`MAX_HANDSHAKE_BYTES` and checks that shape, so a service
that is not a Dask scheduler is named as such in one line and nothing large is allocated.
"""

from __future__ import annotations

import ipaddress
import re
import socket
import struct
import time
from dataclasses import dataclass

from clothlab.errors import ClothlabError

SCHEMES = ("tcp", "tls")
"""Schemes of a scheduler address a command can reach."""
MAX_ADDRESS_CHARS = 300
MAX_HANDSHAKE_BYTES = 1 << 16
"""Most bytes of a Dask handshake read by the probe (a real one is about 60 bytes)."""
_LABEL = re.compile(r"[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?")


@dataclass(frozen=True)
class SchedulerAddress:
    """A checked scheduler address: ``scheme://host:port`` (:attr:`text`), and where it came from
    (``source``: the option or the environment variable, named in every error about it)."""

    scheme: str
    host: str
    port: int
    source: str

    @property
    def text(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"

    def error(self, message: str) -> ClothlabError:
        return ClothlabError(message, field=self.source)


def parse_scheduler_address(text, source: str) -> SchedulerAddress:
    """The :class:`SchedulerAddress` of ``text`` (from ``source``: ``--scheduler`` or
    ``DASK_SCHEDULER_ADDRESS``), or a one-line ClothlabError naming ``source``."""
    def bad(why: str) -> ClothlabError:
        shown = text if len(str(text)) <= 80 else f"{str(text)[:80]}..."
        return ClothlabError(f"{why}; got {shown!r} (expected tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786)",
                             field=source)

    if not isinstance(text, str) or not text:
        raise bad("empty scheduler address")
    if len(text) > MAX_ADDRESS_CHARS:
        raise bad(f"the address has {len(text)} characters; at most {MAX_ADDRESS_CHARS}")
    if not text.isascii() or not text.isprintable() or any(c.isspace() for c in text):
        raise bad("the address holds a space, a control or a non-ASCII character")
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    scheme = scheme.lower()
    if scheme == "inproc":
        raise bad("an inproc:// address exists only inside one Python process; give the tcp:// address of a "
                  "scheduler")
    if scheme not in SCHEMES:
        raise bad(f"unknown scheme {scheme!r}; use one of {', '.join(s + '://' for s in SCHEMES)}")
    if any(c in rest for c in "/?#@"):
        raise bad("the address holds a path, a query or user information; give only HOST:PORT")
    if rest.startswith("["):
        host, bracket, port_text = rest[1:].partition("]")
        if not bracket or not port_text.startswith(":"):
            raise bad("an IPv6 address is written [ADDRESS]:PORT")
        port_text = port_text[1:]
        try:
            host = str(ipaddress.IPv6Address(host))
        except ValueError:
            raise bad(f"{host!r} is not an IPv6 address") from None
    else:
        host, colon, port_text = rest.rpartition(":")
        if not colon:
            raise bad("the port is missing")
        if not host:
            raise bad("the host is missing")
        if ":" in host:
            raise bad("an IPv6 address is written in brackets, [ADDRESS]:PORT")
        if re.fullmatch(r"[0-9.]+", host):
            try:
                host = str(ipaddress.IPv4Address(host))
            except ValueError:
                raise bad(f"{host!r} is not an IPv4 address") from None
        elif len(host) > 253 or not all(_LABEL.fullmatch(label) for label in host.split(".")):
            raise bad(f"{host!r} is not a host name (letters, digits and '-', dot-separated labels)")
    if not re.fullmatch(r"[0-9]{1,5}", port_text):
        raise bad(f"the port {port_text!r} is not a number in decimal digits")
    port = int(port_text)
    if not 1 <= port <= 65535:
        raise bad(f"port {port} lies outside 1-65535")
    return SchedulerAddress(scheme, host, port, source)


def _recv_exactly(sock: socket.socket, n: int, deadline: float) -> bytes:
    chunks, got = [], 0
    while got < n:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError
        sock.settimeout(left)
        chunk = sock.recv(min(n - got, 65536))
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def _connect(address: SchedulerAddress, timeout: float) -> socket.socket:
    """A TCP connection to ``address``, retried (a scheduler starting up) until ``timeout`` seconds passed."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return socket.create_connection((address.host, address.port), timeout=max(0.1, deadline - time.monotonic()))
        except socket.gaierror as exc:
            raise address.error(f"cannot resolve the host of the Dask scheduler address {address.text}: "
                                f"{exc.strerror or exc}") from None
        except OSError as exc:
            if time.monotonic() + 0.2 >= deadline:
                reason = "timed out" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
                raise address.error(f"cannot reach the Dask scheduler at {address.text}: {reason} (after "
                                    f"{timeout:g} s)") from None
            time.sleep(0.2)


def probe_scheduler(address: SchedulerAddress, timeout: float) -> None:
    """Check that a Dask scheduler answers at ``address`` (tcp only: a tls handshake needs Dask's own
    certificates, so a tls address goes to the client directly); a one-line ClothlabError naming the
    address's source otherwise.  Reads at most :data:`MAX_HANDSHAKE_BYTES` within ``timeout`` seconds."""
    if address.scheme != "tcp":
        return
    not_dask = (f"the service at {address.text} is not a Dask scheduler (its first bytes are not a Dask "
                "handshake); check the host and port")
    with _connect(address, timeout) as sock:
        deadline = time.monotonic() + timeout
        try:
            (total,) = struct.unpack("<Q", _recv_exactly(sock, 8, deadline))
            if not 16 <= total <= MAX_HANDSHAKE_BYTES:
                raise address.error(not_dask)
            body = _recv_exactly(sock, total, deadline)
        except TimeoutError:
            raise address.error(f"the service at {address.text} sent no Dask handshake within {timeout:g} s; is it "
                                "a Dask scheduler?") from None
        except EOFError:
            raise address.error(f"the service at {address.text} closed the connection without a Dask handshake; "
                                "is it a Dask scheduler?") from None
        except OSError as exc:
            raise address.error(f"cannot read from the Dask scheduler at {address.text}: "
                                f"{exc.strerror or exc}") from None
    if not _is_handshake(body):
        raise address.error(not_dask)


def _is_handshake(body: bytes) -> bool:
    """True for the frames of a Dask handshake: a frame count, lengths adding up to the rest, and a first
    frame that msgpack reads as a map with ``pickle-protocol``."""
    (count,) = struct.unpack_from("<Q", body)
    if not 1 <= count <= 16 or len(body) < 8 * (1 + count):
        return False
    lengths = struct.unpack_from(f"<{count}Q", body, 8)
    start = 8 * (1 + count)
    if sum(lengths) != len(body) - start:
        return False
    try:
        import msgpack

        header = msgpack.unpackb(body[start:start + lengths[0]], raw=False, strict_map_key=False)
    except Exception:  # noqa: BLE001 - any decoding failure: not a Dask handshake
        return False
    return isinstance(header, dict) and "pickle-protocol" in header
