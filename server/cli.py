"""The ``steelpath`` command: serve, token, plan, estop, emulate.

``serve`` and ``token`` work on the local data directory; ``plan`` talks to a
running server over REST with a token from ``--token``, ``$STEELPATH_TOKEN``
or the token file.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, NoReturn

DEFAULT_URL = "http://127.0.0.1:8000"


def _settings_from(args: argparse.Namespace) -> Any:
    from server.settings import Settings

    overrides: dict[str, Any] = {}
    for attr, key in (
        ("data", "data"),
        ("host", "host"),
        ("port", "port"),
        ("scene_port", "scene_port"),
    ):
        val = getattr(args, attr, None)
        if val is not None:
            overrides[key] = val
    if getattr(args, "no_emulators", False):
        overrides["emulators"] = False
    return Settings(**overrides)


# ----------------------------------------------------------------------- serve
def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from server.app import create_app

    settings = _settings_from(args)
    # A thread waiting for the GIL (the event loop, an E-stop request) gets it
    # from a busy Python thread (a job's result being stored, an upload's
    # chunks) within 1 ms instead of the default 5 ms.
    sys.setswitchinterval(0.001)
    app = create_app(settings)
    print(
        f"SteelPath console: http://{settings.host}:{settings.port}/   "
        f"API docs: http://{settings.host}:{settings.port}/docs   data: {settings.data.resolve()}",
        file=sys.stderr,
        flush=True,
    )
    uvicorn.run(
        app,
        host=settings.host,
        port=settings.port,
        log_level=settings.log_level,
        access_log=settings.access_log,
        ws="websockets-sansio",
        # Event streams and scene sockets never end on their own: bound the wait.
        timeout_graceful_shutdown=3,
        # Longer than a client's own idle expiry (httpx and browsers: 5-60 s),
        # so the client closes an idle connection first.  With uvicorn's 5 s
        # default both ends expired it together and a GET sent in that
        # instant failed "server disconnected" (1 of 15,709 bench reads).
        timeout_keep_alive=75,
    )
    # uvicorn returned after the app's shutdown (links, workers, store closed):
    # end here, without the bindings' teardown report (server.lifetime).
    from server.lifetime import exit_without_teardown

    exit_without_teardown(0)
    return 0  # pragma: no cover


# ----------------------------------------------------------------------- token
def _duration(text: str) -> float:
    """argparse type for ``--expires-in``: ``30d``, ``12h``, ``15m``, ``90s``."""
    from server.auth import parse_duration

    try:
        return parse_duration(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _server_runs_on(data: Path) -> bool:
    """Whether a server holds its run lock on ``data`` (server.store.cleanup.RunLock)."""
    import fcntl

    from server.store.cleanup import LOCK_NAME

    path = Path(data) / LOCK_NAME
    if not path.exists():
        return False
    with open(path, "rb") as fh:
        # A running server holds it shared, so an exclusive try fails; held for
        # an instant, it can at worst make a server starting then clean only
        # stale leftovers.
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
        return False


def cmd_token(args: argparse.Namespace) -> int:
    from server.auth import create_token
    from server.store import NotFoundError, Store

    settings = _settings_from(args)
    fresh = settings.database_url is None and not settings.db_path.exists()
    if fresh and (args.token_cmd != "create" or not args.new_data):
        # A token written where no server looks is refused by the server (401).
        print(
            f"error: no SteelPath database in {settings.data.resolve()} (no server has used "
            "this data directory). Name the server's data directory with --data or "
            "STEELPATH_DATA, or add --new-data to create one here for a server to come.",
            file=sys.stderr,
        )
        return 2
    store = Store(settings.data, database_url=settings.database_url)
    if (
        args.token_cmd == "create"
        and settings.database_url is None
        and not _server_runs_on(settings.data)
    ):
        print(
            f"note: no server runs on {settings.data.resolve()} now; the token works once one "
            "is started with this data directory",
            file=sys.stderr,
        )
    try:
        if args.token_cmd == "create":
            name = args.name or f"{args.role} token"
            tid, secret = create_token(store, name, args.role, "cli", expires_in_s=args.expires_in)
            expiry = store.get_token(tid).expires_at
            until = f", expires {expiry}" if expiry else ", never expires"
            print(f"created {args.role} token {tid} ({name}) in {settings.data}{until}")
            print(secret)
        elif args.token_cmd == "list":
            for t in store.list_tokens():
                if t.revoked_at:
                    state = f"revoked {t.revoked_at}"
                elif t.expired():
                    state = f"expired {t.expires_at}"
                else:
                    state = "active"
                expires = f"expires {t.expires_at}" if t.expires_at else "no expiry"
                print(f"{t.id}\t{t.role}\t{state}\t{expires}\t{t.name}")
        elif args.token_cmd == "revoke":
            try:
                store.revoke_token(args.id, "cli")
            except NotFoundError as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 2
            print(f"revoked {args.id}")
    finally:
        store.close()
    return 0


# ------------------------------------------------------------------------ plan
def _client_token(args: argparse.Namespace) -> str:
    token = args.token or os.environ.get("STEELPATH_TOKEN")
    if not token:
        tf = os.environ.get("STEELPATH_TOKEN_FILE")
        if tf and Path(tf).is_file():
            token = Path(tf).read_text().strip()
    if not token:
        raise SystemExit(
            "error: no token: pass --token, set STEELPATH_TOKEN, or create one with "
            "'steelpath token create --role operator'"
        )
    return token


def _request(args: argparse.Namespace, method: str, path: str, **kw: Any) -> Any:
    import httpx

    url = (args.server or os.environ.get("STEELPATH_URL") or DEFAULT_URL).rstrip("/")
    try:
        r = httpx.request(
            method,
            f"{url}/api/v1{path}",
            headers={"Authorization": f"Bearer {_client_token(args)}"},
            timeout=30.0,
            **kw,
        )
    except httpx.HTTPError as exc:
        raise SystemExit(f"error: cannot reach SteelPath at {url}: {exc}") from None
    if r.status_code >= 400:
        try:
            detail = r.json().get("detail")
        except ValueError:
            detail = r.text
        raise SystemExit(
            f"error: HTTP {r.status_code}: {json.dumps(detail) if not isinstance(detail, str) else detail}"
        )
    return r.json()


def _server_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--server", help=f"server URL (default {DEFAULT_URL}, $STEELPATH_URL)")
    p.add_argument("--token", help="bearer token (default $STEELPATH_TOKEN)")


def _bar(progress: float, stage: str, width: int = 30) -> str:
    done = round(progress * width)
    return f"\r[{'#' * done}{'.' * (width - done)}] {progress * 100:5.1f}% {stage[:40]:<40}"


def _print_plan(plan: dict[str, Any]) -> None:
    print(f"plan {plan['id']}  kind {plan['kind']}  state {plan['state']}")
    if plan.get("error"):
        print(f"  error: {plan['error']}")
    for k, v in sorted((plan.get("metrics") or {}).items()):
        print(f"  {k:32s} {v:.6g}")
    for c in plan.get("checks") or []:
        mark = "PASS" if c["passed"] else "FAIL"
        print(f"  [{mark}] {c['name']}: {c.get('message', '')}")
    if plan.get("allowed_actions"):
        print(f"  allowed actions: {', '.join(plan['allowed_actions'])}")


def _usage_error(message: str) -> NoReturn:
    """One line on stderr and exit status 2 (bad input, as argparse does)."""
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def _read_params(source: str) -> Any:
    """The params JSON in file ``source`` ('-': stdin); empty text is ``{}``.

    A file that cannot be read, or text that is not strict JSON (Python's
    json would read ``NaN`` and ``Infinity``, which the request could then not
    carry), exits 2 with one line naming the file."""
    try:
        text = sys.stdin.read() if source == "-" else Path(source).read_text(encoding="utf-8")
    except OSError as exc:
        _usage_error(f"cannot read params file {source}: {exc.strerror or exc}")
    except UnicodeDecodeError:
        _usage_error(f"params file {source} is not UTF-8 text")
    try:
        return json.loads(text, parse_constant=_refuse_constant) if text.strip() else {}
    except ValueError as exc:  # a JSONDecodeError, or a constant refused above
        _usage_error(f"{source} is not valid JSON: {exc}")


def cmd_plan(args: argparse.Namespace) -> int:
    if args.plan_cmd == "submit":
        params = _read_params(args.params) if args.params else {}
        plan = _request(args, "POST", "/plans", json={"kind": args.kind, "params": params})
        print(f"submitted plan {plan['id']} ({args.kind})", file=sys.stderr)
        if args.no_wait:
            print(plan["id"])
            return 0
        interactive = sys.stderr.isatty()
        last = None
        while plan["state"] in ("queued", "planning"):
            time.sleep(0.3)
            plan = _request(args, "GET", f"/plans/{plan['id']}")
            line = _bar(plan["progress"], f"{plan['state']}: {plan['stage']}")
            if interactive:
                print(line, end="", file=sys.stderr, flush=True)
            elif line != last:
                print(line.strip(), file=sys.stderr, flush=True)
            last = line
        if interactive:
            print(file=sys.stderr)
        _print_plan(plan)
        return 0 if plan["state"] == "planned" else 1
    if args.plan_cmd == "show":
        _print_plan(_request(args, "GET", f"/plans/{args.id}"))
        return 0
    if args.plan_cmd == "list":
        for p in _request(args, "GET", "/plans", params={"limit": args.limit}):
            print(
                f"{p['id']}\t{p['kind']}\t{p['state']}\t{p['progress'] * 100:.0f}%\t{p['created_at']}"
            )
        return 0
    if args.plan_cmd == "params":
        return _print_defaults(args.kind)
    if args.plan_cmd == "approve":
        plan = _request(args, "POST", f"/plans/{args.id}/approve", json={"comment": args.comment})
        print(f"plan {plan['id']} {plan['state']} by {plan.get('approved_by') or '?'}")
        return 0
    if args.plan_cmd == "dispatch":
        ex = _request(args, "POST", f"/plans/{args.id}/dispatch", json={"robot": args.robot})
        print(f"execution {ex['id']} of plan {args.id} on {ex['robot']}: {ex['state']}")
        if args.watch:
            return _watch(args, ex["id"])
        print(ex["id"])
        return 0
    if args.plan_cmd == "watch":
        return _watch(args, _execution_id(args, args.id))
    return 2


#: Execution states a watch stops at (``interrupted`` waits for an operator).
WATCH_STOPS = {"completed": 0, "aborted": 1, "faulted": 1, "interrupted": 1}


def _execution_id(args: argparse.Namespace, ref: str) -> str:
    """An execution id, or a plan id's newest execution."""
    if not ref.startswith("pl_"):
        return ref
    rows = _request(args, "GET", "/executions", params={"plan_id": ref, "limit": 1})
    if not rows:
        raise SystemExit(f"error: plan {ref} has no execution; dispatch it first")
    return str(rows[0]["id"])


def _watch(args: argparse.Namespace, ex_id: str) -> int:
    """Follow an execution until it ends (or needs an operator): one line
    per change of state or acknowledged command; exit 0 only on completed."""
    last = None
    while True:
        ex = _request(args, "GET", f"/executions/{ex_id}")
        line = f"{ex['state']:<11} {ex['acked']}/{ex['total']} commands acknowledged"
        if ex.get("fault") or ex.get("error"):
            line += f"  ({ex.get('fault') or ex.get('error')})"
        if line != last:
            print(f"execution {ex_id}: {line}", flush=True)
            last = line
        if ex["state"] in WATCH_STOPS:
            if ex["state"] == "interrupted":
                print(
                    f"  interrupted: resume with POST /api/v1/executions/{ex_id}/resume "
                    "(the console's Resume) once the robot is safe",
                    flush=True,
                )
            return WATCH_STOPS[ex["state"]]
        time.sleep(args.interval)


def _print_defaults(kind: str) -> int:
    """A kind's default params as JSON (a params file to start from); read
    from the kind's own params model, no server needed."""
    from server.kinds import registry

    kinds = registry()
    if kind not in kinds:
        print(f"error: unknown kind {kind!r}; kinds: {', '.join(sorted(kinds))}", file=sys.stderr)
        return 2
    print(json.dumps(kinds[kind].params_model().model_dump(mode="json"), indent=2))
    return 0


# ----------------------------------------------------------------------- estop
def cmd_estop(args: argparse.Namespace) -> int:
    """E-stop every robot (or one), or clear a latched E-stop."""
    if args.estop_cmd == "clear":
        if bool(args.all) == bool(args.robot):
            raise SystemExit("error: name a robot, or --all to clear every latched robot")
        robots = _request(args, "GET", "/robots")
        known = {r["name"]: r for r in robots}
        if args.robot and args.robot not in known:
            print(f"error: no robot {args.robot!r}; robots: {', '.join(known)}", file=sys.stderr)
            return 2
        for name in [args.robot] if args.robot else list(known):
            if not known[name].get("estop_latched"):
                print(f"{name}: not E-stopped, nothing to clear")
                continue
            after = _request(args, "POST", f"/robots/{name}/clear-estop")
            if after.get("estop_latched"):
                print(f"{name}: clear sent, but the robot still reports its E-stop latched")
            else:
                print(f"{name}: E-stop cleared ({after.get('state', 'state unknown')})")
        return 0
    body: dict[str, Any] = {"reason": args.reason}
    if args.robot:
        body["robot"] = args.robot
    out = _request(args, "POST", "/estop", json=body)
    print(f"E-STOP sent to {args.robot or 'every robot'}: {json.dumps(out)}")
    return 0


# --------------------------------------------------------------------- emulate
def cmd_emulate(argv: list[str]) -> int:
    try:
        from robots.emulator import main as emulator_main
    except ImportError as exc:
        print(f"error: the robot emulator is not available: {exc}", file=sys.stderr)
        return 2
    return int(emulator_main(argv) or 0)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="steelpath",
        description="SteelPath: plan, review, approve and dispatch steel-bridge robot motions.",
    )
    sub = p.add_subparsers(dest="cmd", required=True)

    s = sub.add_parser(
        "serve",
        help="run the API, console and 3D scene",
        description="Start the HTTP API, the operator console and the viser scene.",
    )
    s.add_argument("--host", help="bind address (default 127.0.0.1, $STEELPATH_HOST)")
    s.add_argument("--port", type=int, help="HTTP port (default 8000, $STEELPATH_PORT)")
    s.add_argument(
        "--scene-port", type=int, help="viser port on 127.0.0.1 (default 8081; 0 disables)"
    )
    s.add_argument("--data", type=Path, help="data directory (default ./var, $STEELPATH_DATA)")
    s.add_argument(
        "--no-emulators", action="store_true", help="do not start the built-in robot emulators"
    )
    s.set_defaults(func=cmd_serve)

    t = sub.add_parser(
        "token",
        help="manage API tokens (local data directory)",
        description="Create, list and revoke bearer tokens in the local database.",
    )
    tsub = t.add_subparsers(dest="token_cmd", required=True)
    tc = tsub.add_parser("create", help="create a token and print it (last line)")
    tc.add_argument("--role", choices=["viewer", "operator", "admin"], default="operator")
    tc.add_argument("--name", help="who holds it")
    tc.add_argument(
        "--expires-in",
        type=_duration,
        metavar="DURATION",
        help="lifetime, a number with a unit s, m, h or d (e.g. 30d); default: never expires",
    )
    tc.add_argument(
        "--data", type=Path, help="the server's data directory (default: STEELPATH_DATA or ./var)"
    )
    tc.add_argument(
        "--new-data",
        action="store_true",
        help="create the data directory's database if no server has used it yet",
    )
    tl = tsub.add_parser("list", help="list tokens (never their secrets)")
    tl.add_argument("--data", type=Path)
    tr = tsub.add_parser("revoke", help="revoke a token by id")
    tr.add_argument("id")
    tr.add_argument("--data", type=Path)
    t.set_defaults(func=cmd_token)

    pl = sub.add_parser(
        "plan",
        help="submit and inspect plans on a running server",
        description="Talk to a running server (--server, $STEELPATH_URL).",
    )
    psub = pl.add_subparsers(dest="plan_cmd", required=True)
    for name, helptext in (
        ("submit", "submit a plan and follow its progress"),
        ("show", "show a plan's state, metrics and checks"),
        ("list", "list recent plans"),
        ("params", "print a kind's default params as JSON (a params file to start from)"),
        ("approve", "approve a planned plan whose checks all passed"),
        ("dispatch", "send an approved plan to a robot"),
        ("watch", "follow an execution until it ends"),
    ):
        sp = psub.add_parser(name, help=helptext, description=helptext)
        if name == "params":
            sp.add_argument("kind", help="plan kind, e.g. ara.navigate")
            continue
        _server_args(sp)
        if name == "submit":
            sp.add_argument("kind", help="plan kind, e.g. demo.route")
            sp.add_argument(
                "params", nargs="?", help="params JSON file ('-' for stdin); defaults if omitted"
            )
            sp.add_argument("--no-wait", action="store_true", help="print the plan id and return")
        elif name in ("show", "approve", "dispatch"):
            sp.add_argument("id", help="plan id")
        elif name == "watch":
            sp.add_argument("id", help="execution id, or a plan id for its newest execution")
        else:
            sp.add_argument("--limit", type=int, default=20)
        if name == "approve":
            sp.add_argument("--comment", default="", help="why it is safe to run (audited)")
        if name == "dispatch":
            sp.add_argument("--robot", required=True, help="robot name (GET /robots)")
            sp.add_argument("--watch", action="store_true", help="follow the execution")
        if name in ("dispatch", "watch"):
            sp.add_argument(
                "--interval", type=float, default=0.5, help="seconds between reads (watch)"
            )
    pl.set_defaults(func=cmd_plan)

    es = sub.add_parser(
        "estop",
        help="emergency-stop every robot (or one); 'estop clear' releases the latch",
        description="E-stop: every robot, or --robot NAME.  'steelpath estop clear "
        "NAME|--all' clears a latched E-stop (operator).",
    )
    _server_args(es)
    es.add_argument("--robot", help="one robot (default: every robot)")
    es.add_argument("--reason", default="operator E-stop (CLI)", help="recorded in the audit log")
    esub = es.add_subparsers(dest="estop_cmd")
    ec = esub.add_parser("clear", help="clear a latched E-stop", description="Clear E-stop.")
    _server_args(ec)
    ec.add_argument("robot", nargs="?", help="robot name")
    ec.add_argument("--all", action="store_true", help="every robot")
    es.set_defaults(func=cmd_estop)

    e = sub.add_parser(
        "emulate",
        help="run a robot emulator speaking the SteelPath protocol",
        description="Robot emulator; see 'steelpath emulate --help'.",
        add_help=False,
    )
    e.set_defaults(func=None)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "emulate":
        return cmd_emulate(argv[1:])
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
