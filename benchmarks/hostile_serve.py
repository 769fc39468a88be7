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

    PYTHONPATH=src python benchmarks/hostile_serve.py
"""

from __future__ import annotations

import http.client
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
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


def start_server(folder: Path, *args: str, timeout: float = 120.0) -> tuple[subprocess.Popen, str]:
    """``corl serve --port 0 ARGS`` in ``folder``; returns the process and its URL once it listens."""
    proc = subprocess.Popen([*CORL, "serve", "--port", "0", *args], cwd=folder, env=_env(), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    line = proc.stdout.readline()
    if not line:
        proc.wait(timeout)
        raise RuntimeError(f"corl serve did not start: {proc.stderr.read()[-2000:]}")
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
        ("a second server on the same store", ["--store", "s.corl", "--task", "synthetic", "--token-file", str(good)]),
        ("a port in use", ["--store", "n5.corl", "--task", "synthetic", "--port", port]),
        ("a task that cannot be imported", ["--store", "n6.corl", "--task", "no_such_module:make"]),
        ("an unknown method", ["--store", "n7.corl", "--task", "synthetic", "--method", "bogus"]),
        ("a port out of range", ["--store", "n8.corl", "--task", "synthetic", "--port", "70000"]),
    ]
    results = []
    try:
        for label, args in probes:
            cmd = [*CORL, "serve", *args] if "--port" in args else [*CORL, "serve", "--port", "0", *args]
            try:
                res = subprocess.run(cmd, cwd=folder, env=_env(), capture_output=True, text=True, timeout=120)
                lines = res.stderr.strip().splitlines()
                first = lines[0] if lines else ""
                ok = (res.returncode == 2 and len(lines) == 1 and first.startswith("error: ")
                      and "Traceback" not in res.stderr and res.stdout == "")
                results.append(Result(f"corl serve: {label}", 2, res.returncode, first[:100], ok))
            except subprocess.TimeoutExpired:  # it started serving: the refusal failed
                results.append(Result(f"corl serve: {label}", 2, -1, "kept running", False))
    finally:
        busy.close()
    return results


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
    """``s.corl``: the synthetic task, trial 0 told, trial 1 pending (through the CLI, as a user would)."""
    (folder / "token.txt").write_text(TOKEN + "\n")
    (folder / "token.txt").chmod(0o600)
    for cmd in (["ask", "--raw"], ["tell", "--success", "yes", "--return", "0.5"], ["ask", "--raw"]):
        subprocess.run([*CORL, cmd[0], "--store", "s.corl", "--task", "synthetic", *cmd[1:]], cwd=folder,
                       env=_env(), check=True, capture_output=True, timeout=120)


def run_all(folder: Path) -> list[Result]:
    prepare(folder)
    proc, url = start_server(folder, "--store", "s.corl", "--task", "synthetic", "--token-file", "token.txt")
    try:
        results = request_probes(url)
        results[-1:-1] = command_probes(folder, url)
    finally:
        stop(proc)
    return results


def table(results: list[Result]) -> str:
    width = max(len(r.probe) for r in results)
    lines = [f"{'probe':{width}s}  expected  got  ok  answer"]
    lines += [f"{r.probe:{width}s}  {r.expected:8d}  {r.got:3d}  {'ok' if r.ok else 'NO':2s}  {r.line}" for r in results]
    lines.append(f"{len(results)} probes, {sum(not r.ok for r in results)} failed")
    return "\n".join(lines)


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="corl-hostile-serve-") as tmp:
        t0 = time.perf_counter()
        results = run_all(Path(tmp))
        print(table(results))
        print(f"({time.perf_counter() - t0:.1f} s)")
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
