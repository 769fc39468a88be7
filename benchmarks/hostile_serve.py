"""Hostile requests and command lines against ``corl serve``, as benchmarks/hostile.py probes the CLI.

Two kinds of probe, all on loopback addresses only:

* **command lines** that must be refused at start with one line ``error: ...`` and exit 2: a
  non-loopback bind without a token, bad token files, a second server on the same store (the
  store's writer lock), a port in use, a task that cannot load, flags that contradict the stored run;
* **requests** to a server started with a token on a store whose trial 0 is told and trial 1 pending:
  a missing or wrong token (401), a cookie on a POST (401), an oversized body (413, announced or
  chunked), a body that names a task, method or store (400), a tell of a trial not pending or told
  otherwise (409), a foreign Host header (400), a body that is not JSON (415, 400), NaN and other
  bad outcomes (400), unknown paths and methods (404, 405).

Every answer must be JSON ``{"error": "<one line>"}`` (no traceback, no HTML), every refused request
must leave the store as it was (its told and pending trials), and the run must still work after
them: the last probe tells trial 1 properly. The table prints expected and actual status per probe;
the last lines count the probes that failed, and must read 0.

A third kind, **load**, runs against a server started with a file limit of 1,024 (``ulimit -n``):
a flood of 1,100 connections that each send half a request line and wait, slow headers, slow
bodies with and without the token. During each (until the server has closed every hostile connection,
or for a fixed time when the flood reopens them), a well-behaved client asks ``GET /status`` on a
fresh connection every 0.2 s; its second table prints that client's latency, how many hostile
connections the server dropped and how soon, and how much the server wrote to stderr. Every
well-behaved request must be answered within 5 s, and stderr must stay under 1 MB.

    PYTHONPATH=src python benchmarks/hostile_serve.py            # all three
    PYTHONPATH=src python benchmarks/hostile_serve.py --load     # the load probes only
"""

from __future__ import annotations

import http.client
import json
import os
import resource
import selectors
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

CORL = [sys.executable, "-m", "corl.cli"]
TOKEN = "s3cret-token-of-the-lab-0123456789"


def _env() -> dict[str, str]:
    import corl

    src = str(Path(corl.__file__).resolve().parents[1])
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join(
        [src] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    env.pop("CORL_DEBUG", None)
    return env


@dataclass
class Result:
    probe: str
    expected: int
    got: int
    line: str
    ok: bool


def start_server(folder: Path, *args: str, timeout: float = 120.0, files: int | None = None,
                 stderr=subprocess.PIPE) -> tuple[subprocess.Popen, str]:
    """``corl serve --port 0 ARGS`` in ``folder`` (with ``ulimit -n files`` when given); returns the process
    and its URL once it listens."""
    cmd = [*CORL, "serve", "--port", "0", *args]
    if files is not None:
        cmd = ["sh", "-c", f'ulimit -n {int(files)} && exec "$@"', "sh", *cmd]
    proc = subprocess.Popen(cmd, cwd=folder, env=_env(), text=True, stdout=subprocess.PIPE, stderr=stderr)
    line = proc.stdout.readline()
    if not line:
        proc.wait(timeout)
        raise RuntimeError(f"corl serve did not start: {proc.stderr.read()[-2000:] if proc.stderr else ''}")
    return proc, json.loads(line)["url"]


def stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def request(url: str, method: str, path: str, body: bytes | None = None, headers: dict | None = None,
            chunked: bool = False) -> tuple[int, dict, bytes]:
    host, port = url.rsplit("//", 1)[1].rsplit(":", 1)
    conn = http.client.HTTPConnection(host, int(port), timeout=60)
    try:
        if chunked:
            conn.putrequest(method, path)
            for k, v in (headers or {}).items():
                conn.putheader(k, v)
            conn.putheader("Transfer-Encoding", "chunked")
            conn.endheaders()
            for i in range(0, len(body), 1 << 16):
                part = body[i:i + (1 << 16)]
                try:
                    conn.send(f"{len(part):x}\r\n".encode() + part + b"\r\n")
                except OSError:
                    break  # the server answered and closed: read its answer
            else:
                conn.send(b"0\r\n\r\n")
        else:
            conn.request(method, path, body=body, headers=headers or {})
        response = conn.getresponse()
        return response.status, dict(response.getheaders()), response.read()
    finally:
        conn.close()


def _json_line(status: int, data: bytes) -> tuple[bool, str]:
    """(the body is the JSON one-liner an error must be, its message)."""
    if status == 200 and not data:  # HEAD
        return True, "(no body)"
    try:
        payload = json.loads(data)
    except ValueError:
        return False, data[:80].decode("utf-8", "replace")
    if status < 400:
        return True, json.dumps(payload)[:100]
    message = payload.get("error") if isinstance(payload, dict) else None
    good = isinstance(message, str) and "\n" not in message and "Traceback" not in message and len(payload) == 1
    return good, str(message)[:100]


def command_probes(folder: Path, url: str) -> list[Result]:
    """Command lines ``corl serve`` must refuse (exit 2, one line); the server at ``url`` holds ``s.corl``."""
    good = folder / "token.txt"
    short = folder / "short.txt"
    short.write_text("abc\n")
    short.chmod(0o600)
    shared = folder / "shared.txt"
    shared.write_text(TOKEN + "\n")
    shared.chmod(0o644)
    accent = folder / "accent.txt"
    accent.write_text("s3cret-t\u00f6ken-of-the-lab-0123\n", encoding="utf-8")  # no HTTP header can carry it
    accent.chmod(0o600)
    fifo = folder / "token.fifo"  # would block a reader until a writer came
    if not fifo.exists():
        os.mkfifo(fifo, 0o600)
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = str(busy.getsockname()[1])
    probes = [
        ("non-loopback bind without a token", ["--host", "0.0.0.0", "--store", "n1.corl", "--task", "synthetic"]),
        ("a token file too short", ["--host", "0.0.0.0", "--token-file", str(short), "--store", "n2.corl",
                                    "--task", "synthetic"]),
        ("a token file others can read", ["--token-file", str(shared), "--store", "n3.corl", "--task", "synthetic"]),
        ("a token file that is missing", ["--token-file", "nope.txt", "--store", "n4.corl", "--task", "synthetic"]),
        ("a token file with a non-ASCII character", ["--token-file", str(accent), "--store", "n9.corl", "--task",
                                                     "synthetic"]),
        ("a token file that is a FIFO", ["--token-file", str(fifo), "--store", "n10.corl", "--task", "synthetic"]),
        ("/dev/zero as the token file", ["--token-file", "/dev/zero", "--store", "n11.corl", "--task", "synthetic"]),
        ("a second server on the same store", ["--store", "s.corl", "--task", "synthetic", "--token-file", str(good)]),
        ("a port in use", ["--store", "n5.corl", "--task", "synthetic", "--port", port]),
        ("a task that cannot be imported", ["--store", "n6.corl", "--task", "no_such_module:make"]),
        ("an unknown method", ["--store", "n7.corl", "--task", "synthetic", "--method", "bogus"]),
        ("a port out of range", ["--store", "n8.corl", "--task", "synthetic", "--port", "70000"]),
    ]

    def probe(label: str, args: list[str]) -> Result:
        cmd = [*CORL, "serve", *args] if "--port" in args else [*CORL, "serve", "--port", "0", *args]
        try:
            res = subprocess.run(cmd, cwd=folder, env=_env(), capture_output=True, text=True, timeout=120)
        except subprocess.TimeoutExpired:  # it started serving: the refusal failed
            return Result(f"corl serve: {label}", 2, -1, "kept running", False)
        lines = res.stderr.strip().splitlines()
        first = lines[0] if lines else ""
        ok = (res.returncode == 2 and len(lines) == 1 and first.startswith("error: ")
              and "Traceback" not in res.stderr and res.stdout == "")
        return Result(f"corl serve: {label}", 2, res.returncode, first[:100], ok)

    try:  # two at a time (each its own store): a refused start is mostly its imports
        with ThreadPoolExecutor(max_workers=2) as pool:
            return list(pool.map(lambda p: probe(*p), probes))
    finally:
        busy.close()


def request_probes(url: str) -> list[Result]:
    auth = {"Authorization": f"Bearer {TOKEN}"}
    js = {**auth, "Content-Type": "application/json"}
    big = b'{"raw": true, "pad": "' + b"x" * (2 << 20) + b'"}'
    nested = b"[" * 200_000 + b"]" * 200_000
    probes = [
        ("GET /status without a token", 401, "GET", "/status", None, {}, False),
        ("GET /status with a wrong token", 401, "GET", "/status", None, {"Authorization": "Bearer wrong"}, False),
        ("GET /status with the token's prefix", 401, "GET", "/status", None,
         {"Authorization": f"Bearer {TOKEN[:-1]}"}, False),
        ("GET /status with the token as Basic auth", 401, "GET", "/status", None,
         {"Authorization": f"Basic {TOKEN}"}, False),
        ("GET / with a wrong ?token=", 401, "GET", "/?token=wrong", None, {}, False),
        ("POST /tell with the cookie only", 401, "POST", "/tell", b'{"trial": 1, "success": false}',
         {"Content-Type": "application/json", "Cookie": f"corl_token={TOKEN}"}, False),
        ("POST /ask with a 2 MiB body", 413, "POST", "/ask", big, js, False),
        ("POST /ask with a 2 MiB chunked body", 413, "POST", "/ask", big, js, True),
        ("POST /ask naming a task", 400, "POST", "/ask", b'{"task": "os:system"}', js, False),
        ("POST /tell naming a method", 400, "POST", "/tell",
         b'{"trial": 1, "success": false, "method": "CMA"}', js, False),
        ("POST /ask naming a store", 400, "POST", "/ask", b'{"store": "/etc/passwd"}', js, False),
        ("POST /ask with an unknown field", 400, "POST", "/ask", b'{"rwa": true}', js, False),
        ("POST /tell of a trial not pending", 409, "POST", "/tell", b'{"trial": 5, "success": false}', js, False),
        ("POST /tell of trial 0 told otherwise", 409, "POST", "/tell", b'{"trial": 0, "success": false}', js, False),
        ("POST /ask with no body as text/plain (a cross-site form)", 415, "POST", "/ask", b"",
         {**auth, "Content-Type": "text/plain"}, False),
        ("POST /ask with no body and no type", 415, "POST", "/ask", b"", auth, False),
        ("POST /tell with return 10**400 (an int)", 400, "POST", "/tell",
         b'{"trial": 1, "success": true, "return": 1' + b"0" * 400 + b"}", js, False),
        ("POST /tell with 1e400 inside info", 400, "POST", "/tell",
         b'{"trial": 1, "success": false, "info": {"x": 1e400}}', js, False),
        ("GET /trials?since=\u00b2 (a digit, not ASCII)", 400, "GET", "/trials?since=%C2%B2", None, auth, False),
        ("GET /trials?since= 5000 digits", 400, "GET", "/trials?since=" + "9" * 5000, None, auth, False),
        ("POST /tell as text/plain", 415, "POST", "/tell", b'{"trial": 1, "success": false}',
         {**auth, "Content-Type": "text/plain"}, False),
        ("POST /tell with a NaN return", 400, "POST", "/tell", b'{"trial": 1, "success": true, "return": NaN}',
         js, False),
        ("POST /tell with return 1e999", 400, "POST", "/tell", b'{"trial": 1, "success": true, "return": 1e999}',
         js, False),
        ("POST /tell success as a string", 400, "POST", "/tell", b'{"trial": 1, "success": "yes", "return": 1}',
         js, False),
        ("POST /tell a success without a return", 400, "POST", "/tell", b'{"trial": 1, "success": true}', js, False),
        ("POST /tell a failure with a return", 400, "POST", "/tell",
         b'{"trial": 1, "success": false, "return": 2}', js, False),
        ("POST /tell with trial -1", 400, "POST", "/tell", b'{"trial": -1, "success": false}', js, False),
        ("POST /tell with info not an object", 400, "POST", "/tell",
         b'{"trial": 1, "success": false, "info": [1]}', js, False),
        ("POST /tell with broken JSON", 400, "POST", "/tell", b'{"trial": 1, "succ', js, False),
        ("POST /tell with a JSON array", 400, "POST", "/tell", b"[1, 2]", js, False),
        ("POST /tell nested 200,000 deep", 400, "POST", "/tell", nested, js, False),
        ("POST /tell not UTF-8", 400, "POST", "/tell", b'{"trial": "\xff\xfe"}', js, False),
        ("GET /nowhere", 404, "GET", "/nowhere", None, auth, False),
        ("DELETE /ask", 405, "DELETE", "/ask", None, auth, False),
        ("GET /ask", 405, "GET", "/ask", None, auth, False),
        ("HEAD /events (a stream without end)", 200, "HEAD", "/events", None, auth, False),
        ("GET /trials?since=-1", 400, "GET", "/trials?since=-1", None, auth, False),
        ("GET /figures/../../etc/passwd.png", 404, "GET", "/figures/..%2F..%2Fetc%2Fpasswd.png", None, auth, False),
        ("GET /static/../run.py", 404, "GET", "/static/..%2Frun.py", None, auth, False),
        ("a foreign Host header (DNS rebinding)", 400, "GET", "/status", None, {**auth, "Host": "evil.example"}, False),
        ("POST /tell of trial 0 again, as told", 200, "POST", "/tell",
         b'{"trial": 0, "success": true, "return": %s}', js, False),
    ]
    results = []
    status0, _, data0 = request(url, "GET", "/trials", headers=auth)
    first = json.loads(data0)["trials"][0]
    for label, expected, method, path, body, headers, chunked in probes:
        if body is not None and b"%s" in body:
            body = body % json.dumps(first["return"]).encode()
        try:
            status, _, data = request(url, method, path, body, headers, chunked)
        except (OSError, http.client.HTTPException) as exc:
            results.append(Result(label, expected, -1, f"{type(exc).__name__}: {exc}"[:100], False))
            continue
        good, line = _json_line(status, data)
        results.append(Result(label, expected, status, line, good and status == expected))
    # the browser's way in: ?token= sets a cookie, which then opens GET pages (and only GET)
    status, headers, _ = request(url, "GET", f"/?token={TOKEN}")
    cookie = headers.get("set-cookie", "")
    flags = cookie.lower()
    ok = status == 303 and cookie.startswith("corl_token=") and "httponly" in flags and "samesite=strict" in flags
    results.append(Result("GET /?token=right sets an HttpOnly SameSite cookie", 303, status, cookie[:60], ok))
    status, _, data = request(url, "GET", "/status", headers={"Cookie": cookie.split(";")[0]})
    results.append(Result("GET /status with that cookie", 200, status, data[:60].decode(), status == 200))
    # nothing above changed the run; it still works
    status, _, data = request(url, "GET", "/status", headers=auth)
    s = json.loads(data)
    same = (s["trials"], s["pending"], s["failures"]) == (1, 1, 0)
    results.append(Result("the run is as it was: trial 0 told, trial 1 pending", 200, status, json.dumps(
        {k: s[k] for k in ("trials", "pending", "failures")}), same and status == 200))
    status, _, data = request(url, "POST", "/tell", b'{"trial": 1, "success": false}', js)
    results.append(Result("POST /tell of the pending trial", 200, status, data[:80].decode(), status == 200))
    return results


def prepare(folder: Path) -> None:
    """``s.corl``: the synthetic task, trial 0 told, trial 1 pending (through the CLI, as a user would; run in
    this process, which spares a start-up per command)."""
    from typer.testing import CliRunner

    from corl.cli import app

    (folder / "token.txt").write_text(TOKEN + "\n")
    (folder / "token.txt").chmod(0o600)
    for cmd in (["ask", "--raw"], ["tell", "--success", "yes", "--return", "0.5"], ["ask", "--raw"]):
        res = CliRunner().invoke(app, [cmd[0], "--store", str(folder / "s.corl"), "--task", "synthetic", *cmd[1:]])
        if res.exit_code != 0:
            raise RuntimeError(f"corl {' '.join(cmd)}: exit {res.exit_code}\n{res.output}")


def run_all(folder: Path) -> list[Result]:
    prepare(folder)
    proc, url = start_server(folder, "--store", "s.corl", "--task", "synthetic", "--token-file", "token.txt")
    try:
        results = request_probes(url)
        results[-1:-1] = command_probes(folder, url)
    finally:
        stop(proc)
    return results


# -- load: floods and slow clients against a server with a file limit of 1,024 -----------------------------------------
SERVER_FILES = 1024  # the server's file limit (ulimit -n) in the load probes
FLOOD = 1100  # more connections than the server has files
WELL_BEHAVED_S = 5.0  # a well-behaved request must be answered within this, whatever the load
MIN_ASKS = 12  # a probe asks GET /status at least this often, even when its load is over sooner


@dataclass
class Load:
    probe: str
    opened: int  # hostile connections opened (a connect refused or timed out is not counted)
    dropped: int  # of them, closed by the server while the probe ran
    drop_s: float  # the latest of those closes, seconds after the connection was opened (nan: none)
    answered: int  # well-behaved GET /status answered 200 within WELL_BEHAVED_S
    asked: int
    median_ms: float
    worst_ms: float  # inf: one was not answered
    stderr_bytes: int  # what the server wrote to stderr during the probe
    ok: bool


class Hostiles(threading.Thread):
    """``count`` connections to ``address`` that each send ``first``, then ``trickle`` every second, and
    never finish their request; records when the server closes each. With ``reopen``, each connection
    the server closes is opened again at once, so ``count`` stay open (or try to)."""

    def __init__(self, address: tuple[str, int], count: int, first: bytes, trickle: bytes = b"",
                 reopen: bool = False) -> None:
        super().__init__(name="hostiles", daemon=True)
        self.address, self.count, self.first, self.trickle, self.reopen = address, count, first, trickle, reopen
        self.opened = 0
        self.drops: list[float] = []  # seconds from open to the server's close, per dropped connection
        self.ready = threading.Event()
        self.halt = threading.Event()

    def run(self) -> None:
        selector = selectors.DefaultSelector()
        live: dict[socket.socket, float] = {}

        def open_one() -> None:
            try:
                s = socket.create_connection(self.address, timeout=3.0)
                s.sendall(self.first)
            except OSError:
                return
            s.setblocking(False)
            selector.register(s, selectors.EVENT_READ)
            live[s] = time.monotonic()
            self.opened += 1

        try:
            for _ in range(self.count):
                if self.halt.is_set():
                    break
                open_one()
            self.ready.set()
            next_trickle = time.monotonic() + 1.0
            while not self.halt.is_set():
                for key, _ in selector.select(timeout=0.05):
                    s = key.fileobj
                    try:
                        if s.recv(65536):
                            continue  # an answer (a 408, a 503): the close follows
                    except BlockingIOError:
                        continue
                    except OSError:
                        pass
                    self.drops.append(time.monotonic() - live.pop(s))
                    selector.unregister(s)
                    s.close()
                    if self.reopen and not self.halt.is_set():
                        open_one()
                if self.trickle and time.monotonic() >= next_trickle:
                    next_trickle += 1.0
                    for s in list(live):
                        try:
                            s.send(self.trickle)
                        except OSError:
                            pass  # closed by the server: the select above records it
        finally:
            self.ready.set()
            for s in live:
                s.close()
            selector.close()


def _status_once(url: str, auth: dict) -> float:
    """Seconds one ``GET /status`` takes on a fresh connection (inf: no 200 within WELL_BEHAVED_S)."""
    host, port = url.rsplit("//", 1)[1].rsplit(":", 1)
    t0 = time.monotonic()
    conn = http.client.HTTPConnection(host, int(port), timeout=WELL_BEHAVED_S)
    try:
        conn.request("GET", "/status", headers=auth)
        response = conn.getresponse()
        response.read()
        ok = response.status == 200
    except (OSError, http.client.HTTPException):
        ok = False
    finally:
        conn.close()
    took = time.monotonic() - t0
    return took if ok and took <= WELL_BEHAVED_S else float("inf")


def load_probe(url: str, label: str, count: int, first: bytes, trickle: bytes, seconds: float,
               expect_drop_s: float, reopen: bool = False, *, stderr: Path) -> Load:
    """Run ``count`` hostile connections for ``seconds`` while a well-behaved client asks /status every 0.2 s;
    without ``reopen``, the probe ends sooner once the server has closed every hostile connection (and the
    client has asked at least MIN_ASKS times): the load is over. ok: every well-behaved request answered in
    time, stderr under 1 MB, every hostile connection closed by the server within ``expect_drop_s`` of its
    opening (but those open when the probe ends, with ``reopen``)."""
    auth = {"Authorization": f"Bearer {TOKEN}"}
    host, port = url.rsplit("//", 1)[1].rsplit(":", 1)
    before = stderr.stat().st_size
    hostiles = Hostiles((host, int(port)), count, first, trickle, reopen)
    hostiles.start()
    hostiles.ready.wait(60)
    latencies = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        latencies.append(_status_once(url, auth))
        if not reopen and len(latencies) >= MIN_ASKS and len(hostiles.drops) >= hostiles.opened:
            break  # every hostile connection is closed: the load is over
        time.sleep(0.2)
    hostiles.halt.set()
    hostiles.join(30)
    grown = stderr.stat().st_size - before
    answered = [t for t in latencies if t != float("inf")]
    drops = hostiles.drops
    ok = (len(answered) == len(latencies) and grown < 1_000_000 and hostiles.opened > 0 and bool(drops)
          and max(drops) <= expect_drop_s and (reopen or len(drops) == hostiles.opened))
    return Load(label, hostiles.opened, len(drops), max(drops) if drops else float("nan"), len(answered),
                len(latencies), 1e3 * statistics.median(answered) if answered else float("inf"),
                1e3 * max(latencies) if latencies else float("inf"), grown, ok)


def _raise_file_limit() -> tuple[int, int]:
    """This process's file limit raised to its hard limit (FLOOD sockets need as many files); the old one."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    wanted = hard if hard != resource.RLIM_INFINITY else max(soft, 4 * FLOOD)
    if soft != resource.RLIM_INFINITY and soft < wanted:
        resource.setrlimit(resource.RLIMIT_NOFILE, (wanted, hard))
    return soft, hard


def load_probes(url: str, stderr: Path) -> list[Load]:
    """The floods and slow clients, one after the other, against the server at ``url`` (stderr in ``stderr``)."""
    post = (b"POST /tell HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
            b"Content-Length: 1048576\r\n")
    token = f"Authorization: Bearer {TOKEN}\r\n".encode()
    probes = [
        (f"a flood of {FLOOD:,} idle connections, each sent 'GET /sta'", FLOOD, b"GET /sta", b"", 10.0, 8.0),
        (f"the same flood, each closed connection opened again", FLOOD, b"GET /sta", b"", 10.0, 8.0, True),
        ("300 slow headers (a header line a second, never the end)", 300,
         b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\n", b"X-Slow: 1\r\n", 9.0, 8.0),
        ("300 slow bodies with the token (1 MiB announced, 100 B/s)", 300, post + token + b"\r\n",
         b" " * 100, 14.0, 13.0),
        ("300 slow bodies without the token", 300, post + b"\r\n", b" " * 100, 5.0, 2.0),
    ]
    old = _raise_file_limit()
    try:
        return [load_probe(url, *probe, stderr=stderr) for probe in probes]
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, old)


def run_load(folder: Path) -> list[Load]:
    """The load probes against ``corl serve`` with ``ulimit -n SERVER_FILES`` on ``s.corl`` (prepared), then
    a check that the run is unchanged and still answers."""
    if not (folder / "s.corl").exists():
        prepare(folder)
    log = folder / "serve-stderr.txt"
    with open(log, "w") as err:
        proc, url = start_server(folder, "--store", "s.corl", "--task", "synthetic", "--token-file", "token.txt",
                                 files=SERVER_FILES, stderr=err)
    auth = {"Authorization": f"Bearer {TOKEN}"}
    try:
        before = json.loads(request(url, "GET", "/status", headers=auth)[2])
        results = load_probes(url, log)
        status, _, data = request(url, "GET", "/status", headers=auth)
        after = json.loads(data) if status == 200 else {}
        same = status == 200 and all(after.get(k) == before[k] for k in ("trials", "pending", "failures"))
        results.append(Load("afterwards: GET /status, the run unchanged", 0, 0, float("nan"), int(same), 1,
                            float("nan"), float("nan"), 0, same))
    finally:
        stop(proc)
    return results


def load_table(results: list[Load]) -> str:
    width = max(len(r.probe) for r in results)
    lines = [f"{'load probe (server: ulimit -n ' + str(SERVER_FILES) + ')':{width}s}  opened  dropped  "
             f"last drop  well-behaved /status: answered  median   worst  stderr  ok"]
    for r in results:
        drop = f"{r.drop_s:7.1f} s" if r.drop_s == r.drop_s else "        -"
        med = f"{r.median_ms:6.1f} ms" if r.median_ms == r.median_ms else "        -"
        worst = "timeout" if r.worst_ms == float("inf") else (f"{r.worst_ms:6.0f} ms" if r.worst_ms == r.worst_ms
                                                              else "        -")
        lines.append(f"{r.probe:{width}s}  {r.opened:6d}  {r.dropped:7d}  {drop}  {r.answered:22d}/{r.asked:<3d}"
                     f"  {med}  {worst:>8s}  {r.stderr_bytes:6d}  {'ok' if r.ok else 'NO'}")
    lines.append(f"{len(results)} load probes, {sum(not r.ok for r in results)} failed")
    return "\n".join(lines)


def table(results: list[Result]) -> str:
    width = max(len(r.probe) for r in results)
    lines = [f"{'probe':{width}s}  expected  got  ok  answer"]
    lines += [f"{r.probe:{width}s}  {r.expected:8d}  {r.got:3d}  {'ok' if r.ok else 'NO':2s}  {r.line}" for r in results]
    lines.append(f"{len(results)} probes, {sum(not r.ok for r in results)} failed")
    return "\n".join(lines)


def main() -> int:
    only_load = "--load" in sys.argv[1:]
    with tempfile.TemporaryDirectory(prefix="corl-hostile-serve-") as tmp:
        t0 = time.perf_counter()
        results = [] if only_load else run_all(Path(tmp))
        if results:
            print(table(results))
        loads = run_load(Path(tmp))
        print(load_table(loads))
        print(f"({time.perf_counter() - t0:.1f} s)")
    return 0 if all(r.ok for r in results) and all(r.ok for r in loads) else 1


if __name__ == "__main__":
    sys.exit(main())
