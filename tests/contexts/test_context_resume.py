"""A store with many contexts survives SIGKILL at any moment: rerunning the training resumes every
context exactly where it stopped, and the store ends equal to an uninterrupted one."""

import os
import random
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from corl.store import RunStore
from corl.store.records import EmptyStoreError

CONTEXTS = [[0.0], [0.6], [-0.7], [0.25]]
DRIVER = ("import sys, numpy as np; from pathlib import Path; from corl.experiments.contexts import train; "
          f"train('synthetic-context', 0, np.array({CONTEXTS!r}), Path(sys.argv[1]))")


def content(path):
    """Every run's context and trials (index, step, theta, w, outcome) in order."""
    try:
        db = RunStore(path, readonly=True, create=False)
    except EmptyStoreError:
        return []
    with db:
        return [(info.config.get("context"), info.config.get("contextual"), info.status.value,
                 [(t.proposal.index, t.proposal.step, t.proposal.theta, t.proposal.w,
                   None if t.outcome is None else (t.outcome.success, t.outcome.return_))
                  for t in db.trials(info.id)])
                for info in db.runs()]


def same_trial(a, b) -> bool:
    """Two stored trials are the same: index, step and outcome, theta and w equal up to a few ulps of
    their scale (a resumed process may run another BLAS kernel path, whose last digits differ)."""
    if a[:2] != b[:2] or (a[4] is None) != (b[4] is None):
        return False
    close = all(np.allclose(x, y, rtol=1e-9, atol=1e-12 * (1.0 + np.abs(y).max()))
                for x, y in ((a[2], b[2]), (a[3], b[3])))
    if a[4] is None:
        return close
    return close and a[4][0] == b[4][0] and (a[4][1] is None) == (b[4][1] is None) and (
        a[4][1] is None or abs(a[4][1] - b[4][1]) <= 1e-9 * (1.0 + abs(b[4][1])))


def same_runs(got, want) -> bool:
    return len(got) == len(want) and all(
        g[:3] == w[:3] and len(g[3]) == len(w[3]) and all(same_trial(a, b) for a, b in zip(g[3], w[3]))
        for g, w in zip(got, want))


@pytest.mark.slow
def test_sigkill_while_training_many_contexts_then_resume_equals_uninterrupted(tmp_path):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    ref = tmp_path / "ref.corl"
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", DRIVER, str(ref)], check=True, env=env, capture_output=True)
    duration = time.monotonic() - t0
    expected = content(ref)
    assert len(expected) == len(CONTEXTS) and all(run[2] == "finished" for run in expected)
    assert [run[1] for run in expected] == [True] * len(CONTEXTS)
    assert sum(len(run[3]) for run in expected) > 20
    store = tmp_path / "killed.corl"
    rng = random.Random(11)
    kills = attempts = 0
    while kills < 5 and attempts < 30:
        attempts += 1
        proc = subprocess.Popen([sys.executable, "-c", DRIVER, str(store)], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE)
        time.sleep(rng.uniform(0.2, max(0.5, duration)))
        if proc.poll() is not None:  # finished first: it must be the reference; start over to kill more
            assert proc.returncode == 0, proc.stderr.read().decode()
            assert same_runs(content(store), expected)
            if kills >= 3:
                break
            store.unlink()
            continue
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        kills += 1
        partial = content(store)  # what is stored is a prefix of the reference, run by run
        for got, want in zip(partial, expected):
            assert got[0] == want[0]
            n = len(got[3])
            prefix = all(same_trial(a, b) for a, b in zip(got[3], want[3][:n]))
            pending_last = got[3][-1][4] is None and all(
                same_trial(a, b) for a, b in zip(got[3][:-1], want[3][: n - 1]))
            assert prefix or pending_last
    res = subprocess.run([sys.executable, "-c", DRIVER, str(store)], env=env, capture_output=True)
    assert res.returncode == 0, res.stderr.decode()
    assert same_runs(content(store), expected)
    assert kills >= 3
    contexts = [np.asarray(run[0]) for run in content(store)]  # one store, many contexts
    assert len({c.tobytes() for c in contexts}) == len(CONTEXTS)
