"""The webhook address policy (server/netpolicy.py), offline: the resolver is a stand-in."""

from __future__ import annotations

import socket
from collections.abc import Callable, Sequence
from ipaddress import IPv4Address, IPv4Network, IPv6Address, IPv6Network, ip_address
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from server.netpolicy import OVERRIDABLE, UnsafeWebhookUrl, check_url, kind, parse_ip


def resolver(table: dict[str, list[str]]) -> Callable[..., Sequence[tuple[Any, ...]]]:
    """A getaddrinfo stand-in answering from ``table`` (unknown names fail like DNS)."""

    def resolve(host: str, port: int, *args: Any, **kw: Any) -> list[tuple[Any, ...]]:
        if host not in table:
            raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")
        out: list[tuple[Any, ...]] = []
        for a in table[host]:
            fam = socket.AF_INET6 if ":" in a else socket.AF_INET
            addr = (a, port, 0, 0) if fam == socket.AF_INET6 else (a, port)
            out.append((fam, socket.SOCK_STREAM, 6, "", addr))
        return out

    return resolve


def no_dns(*args: Any, **kw: Any) -> list[tuple[Any, ...]]:
    raise AssertionError("an address literal must not be resolved")


def refusal(url: str, *, allow_private: bool = False, resolve: Any = no_dns) -> str:
    with pytest.raises(UnsafeWebhookUrl) as err:
        check_url(url, allow_private=allow_private, resolve=resolve)
    return str(err.value)


HOSTILE = [
    ("http://127.0.0.1:8080/x", "loopback"),
    ("http://127.1/", "loopback"),
    ("http://2130706433/", "loopback"),
    ("http://0x7f000001/", "loopback"),
    ("http://0177.0.0.1/", "loopback"),
    ("http://[::1]:8000/", "loopback"),
    ("http://[::ffff:127.0.0.1]/", "loopback"),
    ("http://[2002:7f00:1::]/", "loopback"),  # 6to4 of 127.0.0.1
    ("http://0.0.0.0:8000/", "unspecified"),
    ("http://0/", "unspecified"),
    ("http://[::]/", "unspecified"),
    ("http://169.254.169.254/latest/meta-data/", "link-local"),
    ("http://[fe80::1]/", "link-local"),
    ("http://[::ffff:169.254.169.254]/", "link-local"),
    ("http://10.1.2.3/", "private"),
    ("http://172.16.0.1/", "private"),
    ("http://192.168.1.10/", "private"),
    ("http://[fd00::1]/", "private"),
    ("http://[64:ff9b::a00:1]/", "private"),  # NAT64 of 10.0.0.1
    ("http://100.64.0.1/", "shared"),
    ("http://224.0.0.1/", "multicast"),
    ("http://[ff02::1]/", "multicast"),
    ("http://240.0.0.1/", "reserved"),
    ("http://255.255.255.255/", "reserved"),
    ("http://192.0.2.1/", "non-global"),
    ("http://[2001:db8::1]/", "non-global"),
]


@pytest.mark.parametrize(("url", "why"), HOSTILE)
def test_hostile_literals_are_refused_with_the_reason(url: str, why: str) -> None:
    msg = refusal(url)
    assert why in msg and msg.startswith("webhook host "), msg
    if why in OVERRIDABLE:
        assert "unless allow_private_network" in msg
        assert check_url(url, allow_private=True, resolve=no_dns)
    else:
        assert "not even with allow_private_network" in refusal(url, allow_private=True)


def test_names_are_resolved_and_every_address_must_be_public() -> None:
    resolve = resolver(
        {
            "good.example": ["93.184.216.34", "2606:2800:220:1::1", "93.184.216.34"],
            "mixed.example": ["93.184.216.34", "10.0.0.7"],
            "metadata.example": ["169.254.169.254"],
            "localhost": ["127.0.0.1", "::1"],
        }
    )
    assert check_url("https://good.example/hook", allow_private=False, resolve=resolve) == [
        IPv4Address("93.184.216.34"),
        IPv6Address("2606:2800:220:1::1"),
    ]
    msg = refusal("http://mixed.example/", resolve=resolve)
    assert msg.startswith("webhook host mixed.example resolves to 10.0.0.7, a private address")
    assert "loopback" in refusal("http://localhost:8000/", resolve=resolve)
    assert check_url("http://localhost:8000/", allow_private=True, resolve=resolve)
    assert "link-local" in refusal("http://metadata.example/", allow_private=True, resolve=resolve)
    assert "does not resolve" in refusal("http://nowhere.example/", resolve=resolve)
    assert "does not resolve" in refusal(
        "http://empty.example/", resolve=resolver({"empty.example": []})
    )


def test_only_http_and_https_with_a_host_and_a_port() -> None:
    assert "http:// or https://" in refusal("ftp://93.184.216.34/x")
    assert "http:// or https://" in refusal("file:///etc/passwd")
    assert "no host" in refusal("http:///x")
    assert "port" in refusal("http://93.184.216.34:99999/")
    assert check_url("https://93.184.216.34/", allow_private=False, resolve=no_dns)


def test_the_resolver_is_asked_for_the_url_port() -> None:
    asked: list[tuple[str, int]] = []

    def resolve(host: str, port: int, *args: Any, **kw: Any) -> list[tuple[Any, ...]]:
        asked.append((host, port))
        return [(socket.AF_INET, socket.SOCK_STREAM, 6, "", ("93.184.216.34", port))]

    check_url("https://a.example/", allow_private=False, resolve=resolve)
    check_url("http://a.example:8080/", allow_private=False, resolve=resolve)
    assert asked == [("a.example", 443), ("a.example", 8080)]


# ------------------------------------------------------------------ properties
def _form(value: int, radix: str) -> str:
    return {"dec": str(value), "hex": hex(value), "oct": "0" + format(value, "o")}[radix]


@st.composite
def inet_aton_forms(draw: st.DrawFn) -> str:
    """An IPv4 address as inet_aton reads it: 1-4 parts, each in any radix."""
    n_parts = draw(st.integers(1, 4))
    head = [draw(st.integers(0, 255)) for _ in range(n_parts - 1)]
    last = draw(st.integers(0, (1 << (8 * (5 - n_parts))) - 1))
    radix = st.sampled_from(["dec", "hex", "oct"])
    return ".".join(_form(v, draw(radix)) for v in [*head, last])


@given(inet_aton_forms())
def test_ipv4_forms_are_read_as_the_system_reads_them(form: str) -> None:
    """What the resolver would connect to is what the policy judges."""
    ip = parse_ip(form)
    assert ip == IPv4Address(socket.inet_aton(form)), form
    dotted = f"http://{ip}/"
    try:
        check_url(dotted, allow_private=False, resolve=no_dns)
        allowed = True
    except UnsafeWebhookUrl:
        allowed = False
    try:
        check_url(f"http://{form}/", allow_private=False, resolve=no_dns)
        assert allowed, form
    except UnsafeWebhookUrl:
        assert not allowed, form


@given(st.integers(0, 2**32 - 1))
def test_ipv4_in_ipv6_is_judged_as_the_ipv4_address(n: int) -> None:
    v4 = IPv4Address(n)
    assert kind(IPv6Address(f"::ffff:{v4}")) == kind(v4)
    assert kind(IPv6Address((0x0064FF9B << 96) | n)) == kind(v4)  # NAT64
    sixtofour = kind(IPv6Address((0x2002 << 112) | (n << 80)))
    assert sixtofour == kind(v4) or kind(v4) is None


@given(
    st.one_of(
        st.integers(0, 2**32 - 1).map(IPv4Address), st.integers(0, 2**128 - 1).map(IPv6Address)
    )
)
def test_an_allowed_address_is_global_unicast(ip: IPv4Address | IPv6Address) -> None:
    if kind(ip) is None:
        inner = ip.ipv4_mapped if isinstance(ip, IPv6Address) else None
        target = inner or ip
        assert not target.is_multicast and not target.is_loopback and not target.is_private


REFUSED_NETS = [
    "0.0.0.0/8",
    "10.0.0.0/8",
    "100.64.0.0/10",
    "127.0.0.0/8",
    "169.254.0.0/16",
    "172.16.0.0/12",
    "192.168.0.0/16",
    "224.0.0.0/4",
    "240.0.0.0/4",
    "::1/128",
    "fc00::/7",
    "fe80::/10",
    "ff00::/8",
    "::ffff:127.0.0.0/104",
]


@given(st.sampled_from(REFUSED_NETS), st.integers(0, 2**128 - 1))
def test_every_address_of_a_refused_network_is_refused(net: str, offset: int) -> None:
    network = IPv4Network(net) if "." in net and ":" not in net else IPv6Network(net)
    ip = ip_address(int(network.network_address) + offset % network.num_addresses)
    host = f"[{ip}]" if ip.version == 6 else str(ip)
    with pytest.raises(UnsafeWebhookUrl):
        check_url(f"http://{host}/", allow_private=False, resolve=no_dns)
