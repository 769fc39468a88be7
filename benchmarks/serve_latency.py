"""One ask-and-tell round trip through ``corl serve`` against ``corl ask`` + ``corl tell`` from the shell,
at 10, 100 and 1,000 told trials of the synthetic task, in the same run (loopback only).

For each size, a store is filled to that many told trials (CORL+PIBU, seed 7: a run of 1,483 trials,
so there is room to go on), then copied:

* **server**: ``corl serve`` on one copy; a client (:class:`corl.client.Client`, keep-alive) asks,
  rolls the synthetic task out locally and tells, ``--repeats`` times. The table shows the median
  round trip (ask + tell as the client sees them), the learner's own compute and the store's
  commits as the server reports them (``Server-Timing``), and the rest: HTTP, JSON, the event loop.
* **shell**: ``corl ask --raw`` then ``corl tell`` on the other copy, each a new process that replays
  the run from the store, ``--shell-repeats`` times.

    PYTHONPATH=src python benchmarks/serve_latency.py [--sizes 10,100,1000] [--repeats 50]

The issue's targets: the server's round trip without the learner's compute under 50 ms at 1,000
trials, and at least 20x faster than the shell at 100.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SEED = 7
TASK = "synthetic"
CORL = [sys.executable, "-m", "corl.cli"]


def _env() -> dict[str, str]:
    import corl

    src = str(Path(corl.__file__).resolve().parents[1])
    return dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=src)


def fill(store: Path, told: int) -> None:
    """A store whose run has ``told`` trials told and none pending."""
    from corl.session import StoredRun
    from corl.store import RunStore
    from corl.tasks.registry import load_task

    task = load_task(TASK, seed=SEED)
    with RunStore(store) as db:
        run = StoredRun.start(db, task, task_spec=TASK, method="CORL+PIBU", seed=SEED)
        run.run(task, max_trials=told, worker=False)
        assert len(run.history) == told and not run.done


def copy(store: Path, to: Path) -> Path:
    for suffix in ("", "-wal", "-shm"):
        src = Path(str(store) + suffix)
        if src.exists():
            shutil.copy2(src, str(to) + suffix)
    return to


def _timing(header: str) -> tuple[float, float]:
    parts = dict(p.strip().split(";dur=") for p in header.split(","))
    return float(parts["compute"]) / 1e3, float(parts["commit"]) / 1e3


def server_round_trips(store: Path, repeats: int) -> dict:
    """Median seconds of a round trip, the learner's compute, the commits, and the rest."""
    import http.client

    from corl.tasks.registry import load_task

    task = load_task(TASK, seed=SEED)
    proc = subprocess.Popen([*CORL, "serve", "--store", str(store), "--task", TASK, "--port", "0"], env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = json.loads(proc.stdout.readline())["url"]
        host, port = url.rsplit("//", 1)[1].rsplit(":", 1)
        conn = http.client.HTTPConnection(host, int(port), timeout=120)
        headers = {"Content-Type": "application/json"}

        def post(path: str, body: dict) -> tuple[dict, tuple[float, float]]:
            conn.request("POST", path, json.dumps(body), headers)
            r = conn.getresponse()
            data = json.loads(r.read())
            assert r.status == 200, data
            return data, _timing(r.getheader("Server-Timing"))

        rows = []
        for k in range(repeats + 3):  # the first three warm the connection and the caches up
            t0 = time.perf_counter()
            trial, (c1, m1) = post("/ask", {"raw": True})
            t1 = time.perf_counter()
            outcome = task.rollout(np.asarray(trial["w"]))  # the robot, outside the round trip
            t2 = time.perf_counter()
            _, (c2, m2) = post("/tell", {"trial": trial["trial"], "success": outcome.success,
                                         "return": outcome.return_})
            t3 = time.perf_counter()
            if k >= 3:
                rows.append(((t1 - t0) + (t3 - t2), c1 + c2, m1 + m2))
        conn.close()
    finally:
        proc.terminate()
        proc.wait(30)
    total, compute, commit = (np.median([r[i] for r in rows]) for i in range(3))
    return {"round_trip": total, "compute": compute, "commit": commit, "rest": total - compute - commit}


def shell_round_trips(store: Path, repeats: int) -> float:
    """Median seconds of ``corl ask --raw`` + ``corl tell`` from the shell."""
    from corl.tasks.registry import load_task

    task = load_task(TASK, seed=SEED)
    times = []
    folder = store.parent / (store.stem + "-trials")
    for _ in range(repeats):
        t0 = time.perf_counter()
        ask = subprocess.run([*CORL, "ask", "--store", str(store), "--task", TASK, "--raw", "--out", str(folder)],
                             env=_env(), capture_output=True, text=True, check=True)
        t1 = time.perf_counter()
        written = json.loads(ask.stdout.strip().splitlines()[-1])
        outcome = task.rollout(np.load(written["npz"])["w"])
        flags = ["--success", "yes", "--return", repr(outcome.return_)] if outcome.success else ["--success", "no"]
        t2 = time.perf_counter()
        subprocess.run([*CORL, "tell", "--store", str(store), "--task", TASK, *flags], env=_env(),
                       capture_output=True, text=True, check=True)
        times.append((t1 - t0) + (time.perf_counter() - t2))
    return float(np.median(times))


def dashboard_cost(open_dashboard: bool) -> dict:
    """A whole Panda-switch run through ``corl serve`` (22 trials, 500 Hz trajectories of 1,251 x 8 numbers),
    with or without a dashboard's event stream open: medians (s) of the round trip and of the learner's compute."""
    import http.client
    import socket
    import threading

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from examples.panda_switch import make_task

    panda = make_task()
    with tempfile.TemporaryDirectory(prefix="corl-dashboard-cost-") as tmp:
        proc = subprocess.Popen([*CORL, "serve", "--store", str(Path(tmp) / "p.corl"), "--task",
                                 "examples.panda_switch:make_task", "--rate", "500", "--port", "0"],
                                cwd=Path(__file__).resolve().parents[1], env=_env(), stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, text=True)
        try:
            port = int(json.loads(proc.stdout.readline())["url"].rsplit(":", 1)[1])
            if open_dashboard:  # what a browser's EventSource does; the figures are drawn while it listens
                sse = socket.create_connection(("127.0.0.1", port))
                sse.sendall(b"GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
                threading.Thread(target=lambda: [sse.recv(1 << 16) for _ in iter(int, 1)], daemon=True).start()
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
            headers = {"Content-Type": "application/json"}
            rows = []
            while True:
                t0 = time.perf_counter()
                conn.request("POST", "/ask", b"{}", headers)
                r = conn.getresponse()
                trial = json.loads(r.read())
                t1 = time.perf_counter()
                c1, _ = _timing(r.getheader("Server-Timing"))
                outcome = panda.execute(np.array(trial["reference"]["t"]), np.array(trial["reference"]["q"]))
                body = json.dumps({"trial": trial["trial"], "success": outcome.success, "return": outcome.return_})
                t2 = time.perf_counter()
                conn.request("POST", "/tell", body, headers)
                r = conn.getresponse()
                told = json.loads(r.read())
                c2, _ = _timing(r.getheader("Server-Timing"))
                rows.append((t1 - t0 + time.perf_counter() - t2, c1 + c2))
                if told["done"]:
                    break
        finally:
            proc.terminate()
            proc.wait(30)
    return {"trials": len(rows), "round_trip": float(np.median([r[0] for r in rows])),
            "compute": float(np.median([r[1] for r in rows]))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="10,100,1000", help="told trials, comma-separated")
    parser.add_argument("--repeats", type=int, default=50, help="server round trips per size")
    parser.add_argument("--shell-repeats", type=int, default=3, help="shell round trips per size")
    args = parser.parse_args()
    from corl.versions import library_versions

    import starlette
    import uvicorn

    sizes = [int(s) for s in args.sizes.split(",")]
    print(f"synthetic task, CORL+PIBU seed {SEED}; {args.repeats} server / {args.shell_repeats} shell round trips "
          "per size, medians; ms")
    print(" ".join(f"{k} {v}" for k, v in library_versions().items()) +
          f" starlette {starlette.__version__} uvicorn {uvicorn.__version__}")
    header = (f"{'told':>6}  {'server':>8}  {'compute':>8}  {'commit':>7}  {'server w/o compute':>18}  "
              f"{'shell ask+tell':>14}  {'shell / server':>14}")
    print(header)
    results = []
    with tempfile.TemporaryDirectory(prefix="corl-serve-latency-") as tmp:
        for n in sizes:
            base = Path(tmp) / f"filled_{n}.corl"
            fill(base, n)
            served = server_round_trips(copy(base, Path(tmp) / f"served_{n}.corl"), args.repeats)
            shell = shell_round_trips(copy(base, Path(tmp) / f"shell_{n}.corl"), args.shell_repeats)
            results.append((n, served, shell))
            print(f"{n:6d}  {1e3 * served['round_trip']:8.2f}  {1e3 * served['compute']:8.2f}  "
                  f"{1e3 * served['commit']:7.2f}  {1e3 * (served['round_trip'] - served['compute']):18.2f}  "
                  f"{1e3 * shell:14.0f}  {shell / served['round_trip']:13.0f}x", flush=True)
    print("\nwhat an open dashboard costs: examples.panda_switch, a whole run, twice each way, medians in ms")
    print(f"{'dashboard':>9}  {'trials':>6}  {'round trip':>10}  {'compute':>8}  {'rest':>6}")
    for open_dashboard in (False, True, False, True):
        d = dashboard_cost(open_dashboard)
        print(f"{'open' if open_dashboard else 'closed':>9}  {d['trials']:6d}  {1e3 * d['round_trip']:10.1f}  "
              f"{1e3 * d['compute']:8.1f}  {1e3 * (d['round_trip'] - d['compute']):6.1f}", flush=True)
    ok = True
    for n, served, shell in results:
        if n == 1000:
            ok &= served["round_trip"] - served["compute"] < 0.050
            print(f"at 1,000 trials the server's round trip without the learner's compute is "
                  f"{1e3 * (served['round_trip'] - served['compute']):.2f} ms (target < 50 ms)")
        if n == 100:
            ok &= shell / served["round_trip"] >= 20
            print(f"at 100 trials the server is {shell / served['round_trip']:.0f}x faster than the shell "
                  "(target >= 20x)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
