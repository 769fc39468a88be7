"""Helpers of ``RunStore.export``: a run's trials written as a CSV or Parquet table, atomically."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from corl.errors import InputError
from corl.store.files import write_atomically
from corl.store.records import StoreError, TrialRecord

__all__ = ["check_export_path", "write_export"]


def check_export_path(path) -> Path:
    """The export file ``path`` as a Path, or :class:`InputError` saying why it cannot be written."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path} is a folder; give --out a file name such as {path / 'trials.csv'}")
    if path.suffix not in (".csv", ".parquet"):
        raise InputError(f"export writes a .csv or .parquet file, got {path.name!r}; give --out a file name "
                         "ending in .csv or .parquet")
    if not path.parent.is_dir():
        raise InputError(f"the folder {path.parent} to export into does not exist; create it first")
    for target in (path, path.with_suffix(".w.npz")):
        if target.exists() and not target.is_file():
            raise InputError(f"{target} exists and is not a file; choose another --out")
    if not os.access(path.parent, os.W_OK):
        raise InputError(f"the folder {path.parent} is not writable; choose another --out")
    if path.suffix == ".parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise StoreError("exporting to Parquet needs pyarrow: `pip install pyarrow`, or export to .csv") from None
    return path


def write_export(runs: list, path: Path, *, several: bool = False) -> tuple[Path, Path]:
    """Write the trials of ``runs`` (``[(RunInfo, [TrialRecord])]``) to ``path`` and their w vectors to
    ``<name>.w.npz`` (see ``RunStore.export``).

    ``several``: a ``run`` column first (and a ``run`` array in the npz), for the export of many runs.
    A run in a context (``config["context"]``, a task with contexts) gives every row its scene as
    ``context_0..context_{k-1}`` after ``round``; a run without one leaves them empty.
    """
    records = [r for _, trials in runs for r in trials]
    w_shapes = {r.proposal.w.shape for r in records}
    if len(w_shapes) > 1:
        which = f"run {runs[0][0].id}" if not several else f"runs {', '.join(str(i.id) for i, _ in runs)}"
        raise StoreError(f"{which} hold w of several shapes {sorted(w_shapes)}, which cannot be stacked"
                         + ("; export one run at a time (--run ID)" if several else ""))
    scenes = [(info.config or {}).get("context") for info, trials in runs for _ in trials]
    k = max((len(c) for c in scenes if c is not None), default=0)
    columns = _table_columns(records)
    lead: dict[str, list] = {}
    if several:
        lead["run"] = [info.id for info, trials in runs for _ in trials]
    for name in ("index", "step", "round"):
        lead[name] = columns.pop(name)
    for j in range(k):
        lead[f"context_{j}"] = [None if c is None or j >= len(c) else float(c[j]) for c in scenes]
    columns = {**lead, **columns}
    if path.suffix == ".csv":
        _write_atomically(path, lambda f: _write_csv(f, columns), text=True)
    else:
        import pyarrow as pa
        import pyarrow.parquet as pq

        _write_atomically(path, lambda f: pq.write_table(pa.table(columns), f))
    npz = path.with_suffix(".w.npz")
    arrays = {"index": np.array([r.index for r in records], dtype=np.int64),
              "w": np.stack([r.proposal.w for r in records]) if records else np.empty((0, 0))}
    if several:
        arrays["run"] = np.array(lead["run"], dtype=np.int64)
    _write_atomically(npz, lambda f: np.savez(f, **arrays))
    return path, npz


def _table_columns(records: list[TrialRecord]) -> dict[str, list]:
    """The export table as columns; missing values are None."""
    m = max((r.proposal.theta.size for r in records), default=0)
    columns: dict[str, list] = {"index": [], "step": [], "round": []}
    columns.update({f"theta_{j}": [] for j in range(m)})
    columns.update({"success": [], "return": [], "proposed_at": [], "told_at": []})
    for r in records:
        theta = r.proposal.theta.ravel()
        columns["index"].append(r.index)
        columns["step"].append(r.proposal.step)
        columns["round"].append(r.proposal.round)
        for j in range(m):
            columns[f"theta_{j}"].append(float(theta[j]) if j < theta.size else None)
        columns["success"].append(None if r.outcome is None else int(r.outcome.success))
        columns["return"].append(None if r.outcome is None else r.outcome.return_)
        columns["proposed_at"].append(r.proposed_at)
        columns["told_at"].append(r.told_at)
    return columns


def _write_csv(file, columns: dict[str, list]) -> None:
    writer = csv.writer(file)
    writer.writerow(columns)
    for row in zip(*columns.values()):
        writer.writerow(["" if v is None else repr(v) if isinstance(v, float) else v for v in row])


def _write_atomically(path: Path, write, *, text: bool = False) -> None:
    """Write through a temporary file in the same folder, then rename: no half-written exports."""

    def to_file(tmp: Path) -> None:
        with open(tmp, "w" if text else "wb", newline="" if text else None) as f:
            write(f)

    write_atomically(path, to_file)
