"""Where the server may send webhooks: public addresses only (no request forgery).

A webhook URL names a host; :func:`check_url` resolves it and refuses it
unless *every* address it resolves to is a public (global unicast) one, so a
registered webhook cannot make the server POST to itself, its network or its
cloud's metadata service.  Refused: loopback, private (RFC 1918,
``fc00::/7``), shared (``100.64.0.0/10``), link-local (``169.254.0.0/16``,
``fe80::/10``), multicast, unspecified (``0.0.0.0``, ``::``), reserved and any
other non-global address — also when written as IPv4-mapped IPv6
(``::ffff:127.0.0.1``), as 6to4 or NAT64 IPv6, or in the decimal, hex, octal
or short IPv4 forms that ``inet_aton`` (and so the resolver) accepts
(``2130706433``, ``0x7f000001``, ``0177.0.0.1``, ``127.1``).

``allow_private`` (a webhook's ``allow_private_network``, for lab receivers
on the LAN) also lets loopback, private and shared addresses through; never
link-local (the metadata service lives there), multicast, unspecified or
reserved ones.

Pure but for the resolver, which is injected (``resolve``, with
:func:`socket.getaddrinfo`'s signature) so the policy is tested offline.
"""

from __future__ import annotations

import re
import socket
from collections.abc import Callable, Sequence
from ipaddress import IPv4Address, IPv4Network, IPv6Address, IPv6Network, ip_address
from typing import Any
from urllib.parse import urlsplit

Address = IPv4Address | IPv6Address

#: :func:`socket.getaddrinfo` or a stand-in: ``resolve(host, port, type=...)``
#: → ``[(family, type, proto, canonname, sockaddr), ...]``.
Resolver = Callable[..., Sequence[tuple[Any, ...]]]

SCHEMES: dict[str, int] = {"http": 80, "https": 443}

_PRIVATE: tuple[IPv4Network | IPv6Network, ...] = (
    IPv4Network("10.0.0.0/8"),
    IPv4Network("172.16.0.0/12"),
    IPv4Network("192.168.0.0/16"),
    IPv6Network("fc00::/7"),
)
_SHARED = IPv4Network("100.64.0.0/10")
_NAT64 = IPv6Network("64:ff9b::/96")

#: Kinds of address that ``allow_private`` lets through.
OVERRIDABLE = frozenset({"loopback", "private", "shared"})

_DESCRIBED = {
    "unspecified": "an unspecified address",
    "loopback": "a loopback address",
    "link-local": "a link-local address",
    "multicast": "a multicast address",
    "shared": "a shared (carrier-grade NAT) address",
    "private": "a private address",
    "reserved": "a reserved address",
    "non-global": "a non-global address",
}

# One part of an inet_aton address: hex, octal (leading 0) or decimal.
_PART = re.compile(r"0[xX][0-9a-fA-F]*|0[0-7]*|[1-9][0-9]*")


class UnsafeWebhookUrl(ValueError):
    """A webhook URL the server will not send to; the message says why."""


def parse_ip(host: str) -> Address | None:
    """``host`` as the address the resolver would read it as, or None for a name.

    Besides the usual forms, the IPv4 ones of ``inet_aton``: one to four
    dot-separated parts, each decimal, ``0x`` hex or ``0`` octal, the last
    filling the remaining bytes (``127.1`` is 127.0.0.1, ``2130706433`` too).
    """
    try:
        return ip_address(host)
    except ValueError:
        pass
    parts = host.split(".")
    if not 1 <= len(parts) <= 4 or not all(_PART.fullmatch(p) for p in parts):
        return None
    values = [
        int(p[2:] or "0", 16) if p[:2].lower() == "0x" else int(p, 8 if p[0] == "0" else 10)
        for p in parts
    ]
    last_bits = 8 * (5 - len(values))
    if any(v > 0xFF for v in values[:-1]) or values[-1] >= 1 << last_bits:
        return None
    n = values[-1]
    for i, v in enumerate(values[:-1]):
        n |= v << (24 - 8 * i)
    return IPv4Address(n)


def _embedded_v4(ip: IPv6Address) -> IPv4Address | None:
    """The IPv4 address an IPv6 one carries to (mapped, NAT64, 6to4), if any."""
    if ip.ipv4_mapped is not None:
        return ip.ipv4_mapped
    if ip in _NAT64:
        return IPv4Address(int(ip) & 0xFFFFFFFF)
    return ip.sixtofour


def kind(ip: Address) -> str | None:
    """Why ``ip`` is not a public address (a key of :data:`OVERRIDABLE` or
    worse), or None when it is one."""
    if isinstance(ip, IPv6Address):
        inner = _embedded_v4(ip)
        if inner is not None and (why := kind(inner)) is not None:
            return why
        if ip.ipv4_mapped is not None or ip in _NAT64:
            return None  # judged by the IPv4 address it reaches
        ip = IPv6Address(int(ip))  # without a %scope, which changes nothing here
    if ip.is_unspecified:
        return "unspecified"
    if ip.is_loopback:
        return "loopback"
    if ip.is_link_local:
        return "link-local"
    if ip.is_multicast:  # is_global says yes to most multicast
        return "multicast"
    if isinstance(ip, IPv4Address) and ip in _SHARED:
        return "shared"
    if any(ip.version == net.version and ip in net for net in _PRIVATE):
        return "private"
    if ip.is_reserved or (isinstance(ip, IPv4Address) and ip == IPv4Address("255.255.255.255")):
        return "reserved"
    if not ip.is_global:  # documentation, benchmarking, Teredo, ...
        return "non-global"
    return None


def _refusal(host: str, ip: Address, why: str, literal: bool, allow_private: bool) -> str:
    shown = str(ip)
    if isinstance(ip, IPv6Address) and (inner := _embedded_v4(ip)) is not None:
        shown = f"IPv4 {inner} in IPv6"
    if not literal:
        where = f"webhook host {host} resolves to {shown},"
    elif shown == host:
        where = f"webhook host {host} is"
    else:
        where = f"webhook host {host} is {shown},"
    if why in OVERRIDABLE and not allow_private:
        rule = "webhooks go to public addresses only, unless allow_private_network is set"
    else:
        rule = "webhooks are never sent there, not even with allow_private_network"
    return f"{where} {_DESCRIBED[why]}; {rule}"


def check_url(
    url: str, *, allow_private: bool, resolve: Resolver = socket.getaddrinfo
) -> list[Address]:
    """The addresses ``url``'s host resolves to, all allowed, in the resolver's
    order (connect to these, not to a fresh resolution); else
    :class:`UnsafeWebhookUrl`."""
    try:
        parts = urlsplit(url)
    except ValueError as exc:  # e.g. a bracketed host that is no IPv6 address
        raise UnsafeWebhookUrl(f"webhook URL is malformed: {exc}") from exc
    if parts.scheme not in SCHEMES:
        raise UnsafeWebhookUrl(f"webhook URL must be http:// or https://, not {parts.scheme!r}")
    host = parts.hostname
    if not host:
        raise UnsafeWebhookUrl("webhook URL has no host")
    try:
        port = parts.port or SCHEMES[parts.scheme]
    except ValueError as exc:
        raise UnsafeWebhookUrl(f"webhook URL has an invalid port: {exc}") from exc
    literal = parse_ip(host)
    if literal is not None:
        ips = [literal]
    else:
        try:
            infos = resolve(host, port, type=socket.SOCK_STREAM)
        except (OSError, UnicodeError, ValueError) as exc:
            raise UnsafeWebhookUrl(f"webhook host {host} does not resolve") from exc
        ips = []
        for info in infos:
            ip = ip_address(str(info[4][0]).split("%")[0])
            if ip not in ips:
                ips.append(ip)
        if not ips:
            raise UnsafeWebhookUrl(f"webhook host {host} does not resolve")
    for ip in ips:
        why = kind(ip)
        if why is not None and not (allow_private and why in OVERRIDABLE):
            raise UnsafeWebhookUrl(_refusal(host, ip, why, literal is not None, allow_private))
    return ips
