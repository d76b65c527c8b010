"""Webhooks are no request-forgery tool (server/netpolicy.py): registration
refuses hosts on the server's own machine and networks, delivery checks the
host again and posts to the address it checked, and the deliveries list
cannot tell a closed port from an open one.

Names resolve through a stand-in resolver put on the dispatcher (it serves
both checks), so no test needs DNS; receivers are real HTTP servers on
loopback.
"""

from __future__ import annotations

import json
import shutil
import socket
import ssl
import subprocess
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import httpx
import pytest

from server.store.webhooks import WebhookStore
from server.webhooks import UNREACHABLE, WebhookDispatcher
from tests.api.test_webhooks import deliveries, first_in, free_port, receiver, register
from tests.support.serve import ServeProcess
from tests.support.waiting import wait_for

PUBLIC = "93.184.216.34"  # any global unicast address; nothing connects to it here


class FakeDns:
    """A getaddrinfo stand-in; ``table`` may change between calls (rebinding)."""

    def __init__(self, **table: list[str]) -> None:
        self.table = {k.replace("_", "."): v for k, v in table.items()}
        self.asked: list[str] = []

    def __call__(self, host: str, port: int, *args: Any, **kw: Any) -> Sequence[tuple[Any, ...]]:
        self.asked.append(host)
        if host not in self.table:
            raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")
        return [(socket.AF_INET, socket.SOCK_STREAM, 6, "", (a, port)) for a in self.table[host]]


@pytest.fixture
def sapi(make_api: Callable[..., Any]) -> Any:
    """One attempt per delivery, so every outcome is final at once."""
    return make_api(webhook_backoff_s=0.1, webhook_max_attempts=1)


def use_dns(api: Any, dns: FakeDns) -> FakeDns:
    api.services.webhooks.resolve = dns
    return dns


def refused(api: Any, url: str, **body: Any) -> str:
    r = api.post("/api/v1/webhooks", "admin", json={"url": url, **body})
    assert r.status_code == 422, (url, r.status_code, r.text)
    detail = r.json()["detail"]
    assert isinstance(detail, str), detail  # a message for people, not a schema error
    return detail


def failed(api: Any, hook_id: str) -> dict[str, Any]:
    """The newest delivery once it is no longer pending, which must be failed."""
    d = wait_for(
        lambda: (ds := deliveries(api, hook_id)) and ds[0]["state"] != "pending" and ds[0],
        what="the delivery's outcome",
    )
    assert d["state"] == "failed", d
    return d


# ------------------------------------------------------------ registration
HOSTILE = [
    ("http://127.0.0.1:8000/hook", "loopback"),
    ("http://localhost:8000/hook", "loopback"),
    ("http://127.1/", "loopback"),
    ("http://2130706433/", "loopback"),
    ("http://0x7f000001/", "loopback"),
    ("http://0177.0.0.1/", "loopback"),
    ("http://[::1]:8000/", "loopback"),
    ("http://[::ffff:127.0.0.1]/", "loopback"),
    ("http://0.0.0.0:8000/", "unspecified"),
    ("http://[::]/", "unspecified"),
    ("http://169.254.169.254/latest/meta-data/", "link-local"),
    ("http://metadata.example/latest/meta-data/", "link-local"),
    ("http://[fe80::1]/", "link-local"),
    ("http://10.0.0.5/", "private"),
    ("http://172.16.3.4/", "private"),
    ("http://192.168.1.10:8080/", "private"),
    ("http://[fd12:3456::1]/", "private"),
    ("http://mixed.example/", "private"),  # one public address does not make it safe
    ("http://100.64.0.1/", "shared (carrier-grade NAT)"),
    ("http://224.0.0.251/", "multicast"),
    ("http://240.0.0.1/", "reserved"),
]


def test_hostile_hosts_are_refused_at_registration_naming_why(sapi: Any) -> None:
    use_dns(
        sapi,
        FakeDns(
            localhost=["127.0.0.1"],
            metadata_example=["169.254.169.254"],
            mixed_example=[PUBLIC, "10.0.0.7"],
        ),
    )
    for url, why in HOSTILE:
        detail = refused(sapi, url)
        assert f"{why} address" in detail and detail.startswith("webhook host "), (url, detail)
    assert "127.0.0.1, a loopback address" in refused(sapi, "http://0x7f000001/")
    assert "does not resolve" in refused(sapi, "http://nowhere.example/")
    assert sapi.get("/api/v1/webhooks", "admin").json() == []


def test_the_system_resolver_is_used_by_default(sapi: Any) -> None:
    """localhost through the real getaddrinfo (/etc/hosts): no stand-in."""
    assert sapi.services.webhooks.resolve is socket.getaddrinfo
    assert "loopback address" in refused(sapi, "http://localhost:9/hook")


def test_a_public_host_is_registered_without_the_override(sapi: Any) -> None:
    use_dns(sapi, FakeDns(hooks_example=[PUBLIC]))
    hook = register(sapi, "https://hooks.example/in", ["estop"], allow_private=False)
    assert hook["allow_private_network"] is False
    listed = sapi.get(f"/api/v1/webhooks/{hook['id']}", "admin").json()
    assert listed["allow_private_network"] is False


def test_the_override_allows_lan_and_loopback_but_never_link_local(sapi: Any) -> None:
    for url in ("http://10.0.0.5/", "http://192.168.1.10:8080/", "http://100.64.0.1/"):
        assert register(sapi, url, ["estop"])["allow_private_network"] is True
    for url, why in (
        ("http://169.254.169.254/latest/meta-data/", "link-local"),
        ("http://224.0.0.251/", "multicast"),
        ("http://0.0.0.0:8000/", "unspecified"),
    ):
        detail = refused(sapi, url, allow_private_network=True)
        assert why in detail and "not even with allow_private_network" in detail
    audit = sapi.get("/api/v1/audit?entity=webhook", "admin").json()
    assert any("private network allowed" in a["reason"] for a in audit)


def test_with_the_override_a_loopback_receiver_gets_its_delivery(sapi: Any) -> None:
    with receiver() as rx:
        assert "loopback" in refused(sapi, rx.url)
        hook = register(sapi, rx.url, ["estop"], allow_private=True)
        sapi.post("/api/v1/estop", "operator", json={"reason": "lab"})
        d = wait_for(lambda: first_in(deliveries(sapi, hook["id"]), "delivered"), what="delivered")
    assert d["last_status"] == 200 and len(rx.got) == 1


def test_a_hook_at_this_servers_own_api_is_refused(sapi: Any) -> None:
    use_dns(sapi, FakeDns(localhost=["127.0.0.1"]))
    assert "loopback" in refused(sapi, "http://127.0.0.1:8000/api/v1/estop")
    # The TestClient's server is http://testserver (port 80): by its name, and
    # as loopback on its port, even with the override.
    for url in (
        "http://testserver/api/v1/estop",
        "http://127.0.0.1:80/api/v1/estop",
        "http://localhost/api/v1/estop",
    ):
        detail = refused(sapi, url, allow_private_network=True)
        assert "this SteelPath server itself" in detail, (url, detail)


def test_a_real_servers_own_estop_is_refused(tmp_path: Path) -> None:
    """The server on a real socket: its own address is refused as itself
    (before the address policy), with the override too."""
    data = tmp_path / "var"
    data.mkdir()
    srv = ServeProcess(data, "self", emulators="false")
    try:
        for url, body in (
            (f"{srv.url}/api/v1/estop", {}),
            (f"{srv.url}/api/v1/estop", {"allow_private_network": True}),
            (f"http://localhost:{srv.port}/api/v1/estop", {"allow_private_network": True}),
        ):
            r = srv.http.post("/webhooks", json={"url": url, **body})
            assert r.status_code == 422, (url, r.text)
            assert "this SteelPath server itself" in r.json()["detail"]
        assert srv.get("/webhooks") == []
    finally:
        srv.stop()


# ---------------------------------------------------------------- delivery
def test_dns_rebinding_to_loopback_is_not_delivered(sapi: Any) -> None:
    """Public at registration, 127.0.0.1 at delivery: checked again, refused."""
    with receiver() as rx:
        dns = use_dns(sapi, FakeDns(rebind_example=[PUBLIC]))
        hook = register(
            sapi, f"http://rebind.example:{rx.port}/hook", ["estop"], allow_private=False
        )
        dns.table["rebind.example"] = ["127.0.0.1"]
        sapi.post("/api/v1/estop", "operator", json={"reason": "rebind"})
        d = failed(sapi, hook["id"])
        time.sleep(0.3)
    assert rx.got == []
    assert (d["last_status"], d["last_error"]) == (None, UNREACHABLE)
    assert dns.asked.count("rebind.example") == 2  # at registration and at delivery


def test_delivery_goes_to_the_checked_address_with_the_original_host(sapi: Any) -> None:
    """Pinned: the name is resolved once per attempt, by the policy's resolver
    (the system cannot resolve lab.example), and Host still names it."""
    with receiver() as rx:
        dns = use_dns(sapi, FakeDns(lab_example=["127.0.0.1"]))
        hook = register(sapi, f"http://lab.example:{rx.port}/hook", ["estop"], allow_private=True)
        sapi.post("/api/v1/estop", "operator", json={})
        wait_for(lambda: first_in(deliveries(sapi, hook["id"]), "delivered"), what="delivered")
    headers = {k.lower(): v for k, v in rx.got[0][0].items()}
    assert headers["host"] == f"lab.example:{rx.port}"
    assert dns.asked.count("lab.example") == 2


@contextmanager
def redirector(location: str) -> Iterator[int]:
    """A receiver that answers every POST with 302 to ``location``."""

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            self.rfile.read(int(self.headers.get("Content-Length", 0)))
            self.send_response(302)
            self.send_header("Location", location)
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


def test_redirects_are_not_followed(sapi: Any) -> None:
    with receiver() as inner, redirector(inner.url) as port:
        hook = register(sapi, f"http://127.0.0.1:{port}/hook", ["estop"])
        sapi.post("/api/v1/estop", "operator", json={})
        d = failed(sapi, hook["id"])
    assert (d["last_status"], d["last_error"]) == (302, "HTTP 302")
    assert inner.got == []


def test_every_failure_to_connect_reads_the_same(sapi: Any) -> None:
    """Closed port, DNS failure, refused at delivery: one word, no status;
    a receiver that answers (401 here) is the only one with a status."""
    dns = use_dns(sapi, FakeDns(gone_example=["127.0.0.1"], flip_example=["127.0.0.1"]))
    with receiver(statuses=[401]) as rx:
        closed = register(sapi, f"http://127.0.0.1:{free_port()}/hook", ["estop"])
        gone = register(sapi, "http://gone.example:9/hook", ["estop"])
        flip = register(sapi, f"http://flip.example:{rx.port}/hook", ["estop"])
        open_ = register(sapi, rx.url, ["estop"])
        del dns.table["gone.example"]  # the name stops resolving
        dns.table["flip.example"] = ["169.254.169.254"]  # refused even with the override
        sapi.post("/api/v1/estop", "operator", json={})
        got = {h["id"]: failed(sapi, h["id"]) for h in (closed, gone, flip, open_)}
    outcome = {
        k: (d["state"], d["attempts"], d["last_status"], d["last_error"]) for k, d in got.items()
    }
    assert outcome[closed["id"]] == ("failed", 1, None, UNREACHABLE)
    assert outcome[gone["id"]] == outcome[closed["id"]]
    assert outcome[flip["id"]] == outcome[closed["id"]]
    assert outcome[open_["id"]] == ("failed", 1, 401, "HTTP 401")
    assert len(rx.got) == 1  # the flipped name did not reach it


def test_a_timeout_reads_as_unreachable_too(sapi: Any) -> None:
    """A port that takes the connection and never answers: the same word.
    Sent directly, with a short timeout, past the app's own sender (the
    delivery is due only in the far future)."""
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)  # never accepted: the request is never answered
    try:
        db = sapi.services.store.db
        hook = register(sapi, f"http://127.0.0.1:{silent.getsockname()[1]}/hook", ["estop"])
        (d,) = WebhookStore(db).enqueue("estop", {"event": "estop", "data": {}}, time.time() + 1e6)
        sender = WebhookDispatcher(WebhookStore(db), max_attempts=1)
        with httpx.Client(timeout=0.3, follow_redirects=False) as client:
            out = sender.send(client, d)
    finally:
        silent.close()
    assert (out.state, out.last_status, out.last_error) == ("failed", None, UNREACHABLE)
    (listed,) = deliveries(sapi, hook["id"])
    assert listed["last_error"] == UNREACHABLE and json.dumps(listed).count("127.0.0.1") == 0


@contextmanager
def tls_receiver(tmp: Path, name: str) -> Iterator[tuple[int, list[str], ssl.SSLContext]]:
    """An HTTPS receiver on 127.0.0.1 with a self-signed certificate for
    ``name``: its port, the server names (SNI) it was asked for, and a client
    context that trusts it."""
    key, cert = tmp / "key.pem", tmp / "cert.pem"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1"]
        + ["-keyout", str(key), "-out", str(cert), "-subj", f"/CN={name}"]
        + ["-addext", f"subjectAltName=DNS:{name}"],
        check=True,
        capture_output=True,
    )
    snis: list[str] = []
    server_ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    server_ctx.load_cert_chain(cert, key)
    server_ctx.sni_callback = lambda sock, sni, ctx: snis.append(str(sni)) and None

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            self.rfile.read(int(self.headers.get("Content-Length", 0)))
            self.send_response(204)
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    server.socket = server_ctx.wrap_socket(server.socket, server_side=True)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield server.server_address[1], snis, ssl.create_default_context(cafile=str(cert))
    finally:
        server.shutdown()
        server.server_close()


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command")
def test_https_to_the_pinned_address_checks_the_certificate_of_the_name(
    sapi: Any, tmp_path: Path
) -> None:
    """Pinning keeps TLS honest: SNI and the certificate check use the URL's
    name, so the right name is delivered and another name is unreachable."""
    dns = use_dns(sapi, FakeDns(lab_example=["127.0.0.1"], other_example=["127.0.0.1"]))
    with tls_receiver(tmp_path, "lab.example") as (port, snis, client_ctx):
        db = sapi.services.store.db
        sender = WebhookDispatcher(WebhookStore(db), max_attempts=1, resolve=dns)
        outcomes = []
        for name in ("lab.example", "other.example"):
            hook = register(sapi, f"https://{name}:{port}/hook", ["estop"])
            later = time.time() + 1e6  # due only in the far future: the app's sender leaves it
            (d,) = WebhookStore(db).enqueue("estop", {"event": "estop", "data": {}}, later)
            with httpx.Client(verify=client_ctx, timeout=5) as client:
                outcomes.append(sender.send(client, d))
            sapi.delete(f"/api/v1/webhooks/{hook['id']}", "admin")
    ok, wrong_name = outcomes
    assert (ok.state, ok.last_status) == ("delivered", 204)
    assert (wrong_name.state, wrong_name.last_error) == ("failed", UNREACHABLE)
    assert snis == ["lab.example", "other.example"]
