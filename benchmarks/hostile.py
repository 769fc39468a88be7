"""Every bad input of issue 13 against every ``corl`` subcommand, typed as a user would (subprocess).

Each case runs in a fresh folder holding a store (``s.corl``: the synthetic task, trial 0 told,
trial 1 pending), a store whose demonstration is pending after two failed readings (``demo.corl``), a finished run
(``fin.corl``), a run of ``synthetic-context`` in context 0.5 (``ctx.corl``: trial 0 told, trial 1
pending; the skill ``corl policy`` reads), a plain file (``afile.txt``) and a user task module (``usertask.py``, whose
rollouts leave ``rollouts.txt``; some of its factories raise, exit or build tasks whose rollout
does). A few cases run under a resource limit: a file-size limit stands for a full disk (writes
past it fail with EFBIG, no root needed), an address-space limit turns a runaway allocation into
a MemoryError instead of the kernel's OOM kill.
The table shows per case: the command, the input, the exit code, the first line of stderr,
whether every store is unchanged (its bytes and its modification time: a refused command must
not even rewrite SQLite's header), whether the command left any new file or folder behind, and
whether a traceback (or an "internal error") reached the user. The last lines count tracebacks
and refused commands that changed a store; both must read 0.

    PYTHONPATH=src python benchmarks/hostile.py            # every case (~100, about a minute)
    PYTHONPATH=src python benchmarks/hostile.py --fast     # the subset tests/test_hostile.py runs
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

CORL = [sys.executable, "-m", "corl.cli"]


def _env() -> dict[str, str]:
    """The environment of every command: the corl this script imports comes first on the path."""
    import corl

    src = str(Path(corl.__file__).resolve().parents[1])
    paths = [src] + [str(Path(p).resolve()) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", COLUMNS="200", PYTHONPATH=os.pathsep.join(paths))
    env.pop("CORL_DEBUG", None)
    return env

def user_task_source(name: str) -> str:
    """A user task module: ``make`` builds a synthetic task called ``name`` that counts its rollouts in
    ``rollouts.txt`` beside the module; ``boom`` raises, ``not_a_task`` returns 42, ``exits`` calls
    sys.exit(0); ``burning`` and ``leaving`` build tasks whose rollout raises or calls sys.exit(0)."""
    return f"""
import pathlib
import sys
from corl.tasks.synthetic import SyntheticTask

class Counting(SyntheticTask):
    name = {name!r}
    def rollout(self, w):
        log = pathlib.Path(__file__).with_name("rollouts.txt")
        log.write_text(log.read_text() + "x" if log.exists() else "x")
        return super().rollout(w)

def make():
    return Counting((0.6, 0.4))

def boom():
    raise RuntimeError("the factory broke")

def not_a_task():
    return 42

def exits():
    sys.exit(0)

class Burning(Counting):
    def rollout(self, w):
        raise RuntimeError("the robot is on fire")

class Leaving(Counting):
    def rollout(self, w):
        sys.exit(0)

def burning():
    return Burning((0.6, 0.4))

def leaving():
    return Leaving((0.6, 0.4))
"""


USERTASK = user_task_source("synthetic")  # stands in for the synthetic task of the stores


# Damage done to a copy of s.corl (or of a case's target store): (label, SQL) or raw bytes.
DAMAGE = {
    "config not JSON": "UPDATE runs SET config = '{not json'",
    "versions a list": "UPDATE runs SET versions = '[1, 2]'",
    "seed text": "UPDATE runs SET seed = 'abc'",
    "outcome info not JSON": "UPDATE outcomes SET info = 'nope'",
    "w_shape not JSON": "UPDATE trials SET w_shape = '[2' WHERE trial_index = 1",
    "theta_shape negative": "UPDATE trials SET theta_shape = '[-1]' WHERE trial_index = 0",
    "random bytes": b"\x13\x37" * 2048,
    "truncated": None,  # the first 1000 bytes of the store
    "empty file": b"",
}
TASK_SPECS = [":", "..:x", "usertask:", "usertask:boom", "usertask:not_a_task", "nosuchmodule:make", "a b:c"]


@dataclass(frozen=True)
class Case:
    command: str
    label: str
    args: tuple[str, ...]
    damage: str | None = None  # which damage to apply to the store ``target`` first
    limits: tuple[tuple[str, int], ...] = ()  # (RLIMIT_ name, bytes) the command runs under
    target: str = "s.corl"  # the store ``damage`` is done to


FULL_DISK = (("FSIZE", 4096),)  # no file grows past 4 kB: a disk that fills up while a result is written
MEMORY_CAP = (("AS", 4 * 2**30),)  # a runaway allocation is a MemoryError, not the OOM killer
STORES = ("s.corl", "demo.corl", "fin.corl", "ctx.corl")


@dataclass
class Result:
    case: Case
    code: int
    first_line: str
    unchanged: bool
    left: list[str]
    traceback: bool


def _reader_cmds(store: str) -> dict[str, list[str]]:
    return {
        "status": ["status", "--store", store],
        "runs": ["runs", "--store", store],
        "export": ["export", "--store", store, "--out", "t.csv"],
        "report": ["report", "--store", store, "--out", "rep", "--no-video", "--task", "synthetic"],
        "ask": ["ask", "--store", store, "--task", "synthetic", "--raw"],
        "tell": ["tell", "--store", store, "--task", "synthetic", "--success", "yes", "--return", "0.1"],
        "run --resume": ["run", "synthetic", "--store", store, "--resume", "--out", "o", "--no-video", "-q"],
    }


def cases() -> list[Case]:
    out: list[Case] = []
    for damage in DAMAGE:  # damaged stores against every command that opens a store
        for command, args in _reader_cmds("s.corl").items():
            out.append(Case(command, f"store: {damage}", tuple(args), damage))
    for command, args in _reader_cmds("nothere.corl").items():
        if command not in ("ask", "run --resume"):  # these two start a new store: not an error
            out.append(Case(command, "store missing", tuple(args)))
    for command, args in _reader_cmds("sub").items():
        out.append(Case(command, "store is a folder", tuple(args)))
    for spec in TASK_SPECS:  # task specs against every command that takes a task
        out += [Case("run", f"task {spec!r}", ("run", spec, "--out", "o", "--no-video", "-q")),
                Case("ask", f"task {spec!r}", ("ask", "--store", "new.corl", "--task", spec)),
                Case("tell", f"task {spec!r}", ("tell", "--store", "s.corl", "--task", spec, "--success", "yes",
                                                "--return", "0.1")),
                Case("report", f"task {spec!r}", ("report", "--store", "s.corl", "--out", "rep", "--task", spec))]
    out += [
        Case("run", "--seed -1", ("run", "usertask:make", "--seed", "-1", "--out", "o", "-q")),
        Case("run", "--seed 2^64", ("run", "usertask:make", "--seed", str(2**64), "--out", "o", "-q")),
        Case("run", "--method NOPE", ("run", "usertask:make", "--method", "NOPE", "--out", "o", "-q")),
        Case("run", "--out FILE", ("run", "usertask:make", "--out", "afile.txt", "-q")),
        Case("run", "--out under a FILE", ("run", "usertask:make", "--out", "afile.txt/o", "-q")),
        Case("run", "--resume --seed other", ("run", "synthetic", "--store", "s.corl", "--resume", "--seed", "5",
                                              "--out", "o", "-q")),
        *[Case("run", f"{flag} {v}", ("run", "usertask:make", flag, v, "--out", "o", "-q"))
          for flag, v in (("--return-noise", "-1"), ("--return-noise", "nan"), ("--flip", "0.5"))],
        Case("run", "--resume --flip other", ("run", "synthetic", "--store", "s.corl", "--resume", "--flip", "0.1",
                                              "--out", "o", "-q")),
        Case("ask", "--seed -1", ("ask", "--store", "new.corl", "--task", "usertask:make", "--seed", "-1")),
        Case("ask", "--method NOPE", ("ask", "--store", "new.corl", "--task", "usertask:make", "--method", "NOPE")),
        Case("ask", "--out FILE", ("ask", "--store", "new.corl", "--task", "usertask:make", "--out", "afile.txt")),
        *[Case("ask", f"--rate {r}", ("ask", "--store", "new.corl", "--task", "usertask:make", "--rate", r))
          for r in ("nan", "inf", "1e12", "0", "-5")],
        Case("tell", "demonstration --success no", ("tell", "--store", "demo.corl", "--task", "synthetic",
                                                    "--success", "no")),
        Case("tell", "--success no --return 0.3", ("tell", "--store", "s.corl", "--task", "synthetic",
                                                   "--success", "no", "--return", "0.3")),
        Case("tell", "--success maybe", ("tell", "--store", "s.corl", "--task", "synthetic", "--success", "maybe")),
        Case("tell", "--success yes (no return)", ("tell", "--store", "s.corl", "--task", "synthetic",
                                                   "--success", "yes")),
        *[Case("tell", f"--return {r}", ("tell", "--store", "s.corl", "--task", "synthetic", "--success", "yes",
                                         "--return", r)) for r in ("nan", "inf", "lots")],
        Case("status", "--run 99", ("status", "--store", "s.corl", "--run", "99")),
        Case("status", "--run 2^70", ("status", "--store", "s.corl", "--run", str(2**70))),
        Case("export", "--out DIR", ("export", "--store", "s.corl", "--out", "sub")),
        Case("export", "--out .xlsx", ("export", "--store", "s.corl", "--out", "t.xlsx")),
        Case("export", "--out in missing folder", ("export", "--store", "s.corl", "--out", "nofolder/t.csv")),
        Case("report", "--out FILE", ("report", "--store", "s.corl", "--out", "afile.txt")),
        Case("report", "--run 99", ("report", "--store", "s.corl", "--out", "rep", "--run", "99")),
        Case("bench synthetic", "--seed -1", ("bench", "synthetic", "--seed", "-1", "--starts", "1", "--out", "b")),
        Case("bench synthetic", "--jobs 0", ("bench", "synthetic", "--jobs", "0", "--starts", "1", "--out", "b")),
        Case("bench synthetic", "--jobs -5", ("bench", "synthetic", "--jobs", "-5", "--starts", "1", "--out", "b")),
        Case("bench synthetic", "--starts 0", ("bench", "synthetic", "--starts", "0", "--out", "b")),
        Case("bench synthetic", "--out FILE", ("bench", "synthetic", "--starts", "1", "--out", "afile.txt")),
        Case("bench synthetic", "--methods NOPE", ("bench", "synthetic", "--methods", "NOPE", "--out", "b")),
        Case("bench door", "--jobs 0", ("bench", "door", "--jobs", "0", "--out", "d")),
        Case("bench door", "--out FILE", ("bench", "door", "--out", "afile.txt")),
        Case("bench door", "--grid 1x0", ("bench", "door", "--grid", "1x0", "--out", "d")),
        Case("bench door", "--force-noise nan", ("bench", "door", "--force-noise", "nan", "--out", "d")),
        Case("bench synthetic", "--methods ','", ("bench", "synthetic", "--methods", ",", "--out", "b")),
        Case("bench synthetic", "--starts 200000000", ("bench", "synthetic", "--starts", "200000000", "--out", "b")),
        *_sweep_cases(), *_run_cases(), *_context_cases(),
    ]
    return out


def _sweep_cases() -> list[Case]:
    def sweep(label: str, *args: str, task: str = "synthetic", limits=()) -> Case:
        return Case("sweep", label, ("sweep", task, "-q", *args), limits=limits)

    return [
        sweep("--jobs 0", "--grid", "5", "--jobs", "0", "--out", "sw"),
        sweep("--seed -1", "--grid", "5", "--seed", "-1", "--out", "sw"),
        sweep("--out FILE", "--grid", "5", "--out", "afile.txt"),
        sweep("--out read-only place", "--grid", "5", "--out", "/proc/corl-hostile-sweep"),
        sweep("--grid 1000000000", "--grid", "1000000000", "--out", "sw", limits=MEMORY_CAP),
        sweep("--grid 1x0", "--grid", "1x0", "--out", "sw"),
        sweep("full disk", "--grid", "400", "--out", "sw", limits=FULL_DISK),
        sweep("task ':'", "--grid", "5", "--out", "sw", task=":"),
        sweep("factory sys.exit(0)", "--grid", "5", "--out", "sw", task="usertask:exits"),
        sweep("rollout raises", "--grid", "5", "--out", "sw", task="usertask:burning"),
        sweep("rollout sys.exit(0)", "--grid", "5", "--out", "sw", task="usertask:leaving"),
        sweep("rollout raises, --jobs 2", "--grid", "5", "--out", "sw", "--jobs", "2", task="usertask:burning"),
    ]


def _run_cases() -> list[Case]:
    """The stored-run refusals of the hostile pass of issue 14: flags that differ from the stored run, a
    finished run, a return Python reads too generously, user code that exits, a full disk."""
    tell = ("tell", "--store", "s.corl", "--success", "yes", "--return")
    return [
        Case("ask", "--method/--seed other", ("ask", "--store", "s.corl", "--task", "synthetic", "--raw",
                                              "--method", "CORL+UCB", "--seed", "7")),
        Case("ask", "finished run", ("ask", "--store", "fin.corl", "--task", "synthetic", "--raw")),
        Case("ask", "factory sys.exit(0)", ("ask", "--store", "s.corl", "--task", "usertask:exits", "--raw")),
        Case("tell", "--return 1_000", (*tell, "1_000", "--task", "synthetic")),
        Case("tell", "factory sys.exit(0)", (*tell, "0.1", "--task", "usertask:exits")),
        Case("tell", "nothing pending", ("tell", "--store", "fin.corl", "--task", "synthetic", "--success", "no")),
        Case("run --resume", "--method other", ("run", "synthetic", "--store", "s.corl", "--resume", "--method",
                                                "CORL+CMA", "--out", "o", "-q")),
        Case("run --resume", "factory sys.exit(0)", ("run", "usertask:exits", "--store", "s.corl", "--resume",
                                                     "--out", "o", "-q")),
        Case("report", "full disk (figures)", ("report", "--store", "s.corl", "--out", "rep", "--no-video",
                                               "--task", "synthetic", "-q"), limits=FULL_DISK),
        Case("report", "full disk (page)", ("report", "--store", "demo.corl", "--out", "rep", "--no-video", "-q"),
             limits=FULL_DISK),  # nothing told yet, no --task: no figure, the page itself hits the limit
    ]


def _context_cases() -> list[Case]:
    """``--context`` of ``corl run`` and ``corl ask``, and ``corl policy``: a context that is no point of the
    task's context box, a task without contexts, a method that cannot learn in a context, another context
    than the unfinished run's, a store that learned no context."""
    run = ("run", "synthetic-context", "--out", "o", "--no-video", "-q", "--store", "new.corl", "--context")
    ask = ("ask", "--store", "new.corl", "--task", "synthetic-context", "--raw", "--context")
    policy = ("policy", "synthetic-context", "--store", "ctx.corl", "--out", "pol", "--context")
    bad = {"--context 0.1,0.2 (count)": "0.1,0.2", "--context nan": "nan", "--context 1e999": "1e999",
           "--context 1.5 (outside)": "1.5", "--context ''": "", "--context 0.1,,0.2": "0.1,,0.2"}
    out = [Case(command, label, (*args, text)) for label, text in bad.items()
           for command, args in (("run", run), ("ask", ask), ("policy", policy))]
    for damage in DAMAGE:  # a damaged store that a new run in a context, or the skill, is read from
        out += [Case("policy", f"ctx store: {damage}", (*policy, "0.2"), damage, target="ctx.corl"),
                Case("run", f"--context, ctx store: {damage}", (*run[:-2], "ctx.corl", "--context", "-0.5"), damage,
                     target="ctx.corl"),
                Case("ask", f"--context, ctx store: {damage}", ("ask", "--store", "ctx.corl", "--task",
                                                                "synthetic-context", "--raw", "--context", "0.5"),
                     damage, target="ctx.corl")]
    return out + [
        Case("run", "--context, task has none", ("run", "synthetic", "--out", "o", "-q", "--context", "0.1")),
        Case("ask", "--context, task has none", ("ask", "--store", "new.corl", "--task", "synthetic", "--raw",
                                                 "--context", "0.1")),
        Case("policy", "task has no contexts", ("policy", "synthetic", "--store", "ctx.corl", "--context", "0.1")),
        Case("run", "--context --method CORL+CMA", (*run, "0.1", "--method", "CORL+CMA")),
        Case("ask", "--context --method CORL+CMA", (*ask, "0.1", "--method", "CORL+CMA")),
        Case("run", "--context --method CORL+CMA (store)", ("run", "synthetic-context", "--store", "ctx.corl",
                                                            "--out", "o", "-q", "--context", "0.1", "--method",
                                                            "CORL+CMA")),
        Case("run --resume", "--context other", ("run", "synthetic-context", "--store", "ctx.corl", "--resume",
                                                 "--context", "-0.5", "--out", "o", "--no-video", "-q")),
        Case("ask", "--context other, run unfinished", ("ask", "--store", "ctx.corl", "--task", "synthetic-context",
                                                         "--raw", "--context", "-0.5")),
        Case("ask", "--context, s.corl unfinished", ("ask", "--store", "s.corl", "--task", "synthetic-context",
                                                     "--raw", "--context", "0.1")),
        Case("ask", "--context, no --raw", ("ask", "--store", "ctx.corl", "--task", "synthetic-context",
                                            "--context", "0.5")),
        Case("policy", "store learned no context", ("policy", "synthetic-context", "--store", "s.corl",
                                                    "--context", "0.1", "--out", "pol")),
        Case("policy", "store missing", ("policy", "synthetic-context", "--store", "nothere.corl", "--context",
                                         "0.1")),
        Case("policy", "--out FILE", (*policy[:-3], "--out", "afile.txt", "--context", "0.1")),
        Case("policy", "--rate 0", (*policy, "0.1", "--rate", "0")),
        Case("policy", "store is a folder", ("policy", "synthetic-context", "--store", "sub", "--context", "0.1")),
    ]


# The subset tests/test_hostile.py runs: one case of each kind, every subcommand at least once.
FAST = {("status", "store: config not JSON"), ("export", "store: w_shape not JSON"), ("runs", "store: random bytes"),
        ("run --resume", "store: versions a list"), ("run", "task ':'"), ("ask", "task '..:x'"),
        ("tell", "task 'usertask:boom'"), ("report", "task 'usertask:not_a_task'"), ("run", "--seed -1"),
        ("ask", "--rate 1e12"), ("export", "--out DIR"), ("tell", "demonstration --success no"),
        ("tell", "--success no --return 0.3"), ("bench synthetic", "--jobs 0"), ("bench door", "--jobs 0"),
        ("sweep", "--jobs 0"), ("sweep", "rollout raises"), ("sweep", "full disk"), ("ask", "--method/--seed other"),
        ("ask", "finished run"), ("tell", "--return 1_000"), ("tell", "factory sys.exit(0)"),
        ("report", "full disk (figures)"), ("report", "full disk (page)"), ("bench synthetic", "--methods ','"),
        ("run", "--context nan"), ("ask", "--context other, run unfinished"), ("policy", "ctx store: outcome info not JSON"),
        ("run --resume", "--context other")}


def prepare(folder: Path) -> None:
    """The template every case copies: stores, a file, a folder and the user task. The stores are made by
    corl's command line run in this process (CliRunner, absolute paths: a store holds none), which spares
    a start-up per command; the cases themselves run as subprocesses."""
    from typer.testing import CliRunner

    from corl.cli import app

    def corl(command: str, store: str, *args: str) -> None:
        args = tuple(str(folder / a) if a == "trials" else a for a in args)
        res = CliRunner().invoke(app, [command, "--store", str(folder / store), *args])
        if res.exit_code != 0:
            raise RuntimeError(f"corl {command} --store {store} {' '.join(args)}: exit {res.exit_code}\n{res.output}")

    (folder / "usertask.py").write_text(USERTASK)
    (folder / "afile.txt").write_text("a file, not a folder\n")
    (folder / "sub").mkdir()
    corl("ask", "demo.corl", "--task", "synthetic", "--out", "trials", "--raw")
    shutil.copy(folder / "demo.corl", folder / "s.corl")
    corl("tell", "s.corl", "--task", "synthetic", "--success", "yes", "--return", "0.2")
    corl("ask", "s.corl", "--task", "synthetic", "--out", "trials", "--raw")
    shutil.copy(folder / "s.corl", folder / "fin.corl")  # a run marked finished, as `corl run` leaves one
    with contextlib.closing(sqlite3.connect(folder / "fin.corl")) as db, db:
        db.execute("DELETE FROM trials WHERE trial_index = 1")  # nothing pending
        db.execute("UPDATE runs SET status = 'finished'")
    for _ in range(2):  # demo.corl: the demonstration read twice as failed (start_retries) and asked a third time
        corl("tell", "demo.corl", "--task", "synthetic", "--success", "no")
        corl("ask", "demo.corl", "--task", "synthetic", "--out", "trials", "--raw")
    corl("ask", "ctx.corl", "--task", "synthetic-context", "--context", "0.5", "--out", "trials", "--raw")
    corl("tell", "ctx.corl", "--task", "synthetic-context", "--success", "yes", "--return", "0.9")
    corl("ask", "ctx.corl", "--task", "synthetic-context", "--out", "trials", "--raw")


def _damage(store: Path, damage: str) -> None:
    spec = DAMAGE[damage]
    if damage == "truncated":
        store.write_bytes(store.read_bytes()[:1000])
    elif isinstance(spec, bytes):
        store.write_bytes(spec)
    else:
        with contextlib.closing(sqlite3.connect(store)) as db, db:
            db.execute(spec)


def _state(folder: Path) -> tuple[list[str], dict[str, tuple[bytes, int]]]:
    """(every path under ``folder``, each store's bytes and modification time in ns)."""
    paths = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if "__pycache__" not in p.parts)
    stores = {name: ((folder / name).read_bytes(), (folder / name).stat().st_mtime_ns) for name in STORES}
    return paths, stores


def _command(case: Case) -> list[str]:
    """The command line of ``case``: ``python -m corl.cli ...``, under its resource limits if it has any."""
    if not case.limits:
        return CORL + list(case.args)
    limits = "; ".join(f"resource.setrlimit(resource.RLIMIT_{name}, ({value}, {value}))" for name, value in case.limits)
    launcher = f"import resource, sys; {limits}; from corl.cli import main; sys.argv[0] = 'corl'; sys.exit(main())"
    return [sys.executable, "-c", launcher, *case.args]


def run_case(case: Case, template: Path) -> Result:
    with tempfile.TemporaryDirectory(prefix="corl-hostile-") as tmp:
        folder = Path(tmp) / "case"
        shutil.copytree(template, folder)
        if case.damage is not None:
            _damage(folder / case.target, case.damage)
        paths, stores = _state(folder)
        res = subprocess.run(_command(case), cwd=folder, env=_env(), capture_output=True, text=True, timeout=300)
        after_paths, after_stores = _state(folder)
        left = sorted(set(after_paths) - set(paths))
        lines = res.stderr.strip().splitlines()
        traceback = "Traceback" in res.stderr + res.stdout or "internal error" in res.stderr
        return Result(case, res.returncode, lines[0] if lines else "", after_stores == stores, left, traceback)


def table(results: list[Result], width: int = 96) -> str:
    rows = [f"| {'command':<15} | {'input':<28} | exit | {'first line of stderr':<{width}} | unchanged | left | tb |",
            f"|{'-' * 17}|{'-' * 30}|------|{'-' * (width + 2)}|-----------|------|----|"]
    for r in results:
        line = r.first_line if len(r.first_line) <= width else r.first_line[:width - 3] + "..."
        rows.append(f"| {r.case.command:<15} | {r.case.label[:28]:<28} | {r.code:>4} | {line:<{width}} | "
                    f"{'yes' if r.unchanged else 'NO':<9} | {len(r.left):>4} | {'YES' if r.traceback else '':<2} |")
    return "\n".join(rows)


def run_all(selected: list[Case], workers: int = 2) -> list[Result]:
    with tempfile.TemporaryDirectory(prefix="corl-hostile-template-") as tmp:
        template = Path(tmp)
        prepare(template)
        with ThreadPoolExecutor(max_workers=workers) as pool:
            return list(pool.map(lambda c: run_case(c, template), selected))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fast", action="store_true", help="only the subset the test suite runs")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    selected = [c for c in cases() if not args.fast or (c.command, c.label) in FAST]
    results = run_all(selected, workers=args.workers)
    print(table(results))
    tracebacks = sum(r.traceback for r in results)
    succeeded = sum(r.code == 0 for r in results)
    changed = sum(not r.unchanged for r in results)
    changed_refused = sum(not r.unchanged and r.code != 0 for r in results)
    left = sum(bool(r.left) for r in results)
    print(f"\n{len(results)} cases: {tracebacks} tracebacks or internal errors, {succeeded} accepted (exit 0), "
          f"{changed} changed a store's bytes or mtime ({changed_refused} of them refused), {left} left files behind")
    for r in results:
        if r.left or (not r.unchanged and r.code != 0):
            print(f"  {r.case.command} {r.case.label}: exit {r.code}, "
                  f"{'left ' + ', '.join(r.left) if r.left else 'changed a store'}")
    return 1 if tracebacks or changed_refused else 0


if __name__ == "__main__":
    sys.exit(main())
