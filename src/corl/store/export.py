"""Helpers of ``RunStore.export``: a run's trials written as a CSV or Parquet table, atomically."""

from __future__ import annotations

import csv
import os
import tempfile
from pathlib import Path

from corl.store.records import TrialRecord


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
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with open(fd, "w" if text else "wb", newline="" if text else None) as f:
            write(f)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
