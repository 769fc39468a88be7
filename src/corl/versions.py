"""Versions of the software a result was computed with, recorded beside every run.

The learner is deterministic given its seed only for fixed library versions: numpy, scipy, the
BLAS numpy links and MuJoCo can change results in the last bits. :func:`library_versions` is
stored with each run, and :func:`version_differences` explains a failed exact resume.

Nothing here imports the libraries it reports on (MuJoCo is slow to import); the versions come
from the installed package metadata.
"""

from __future__ import annotations

import platform
from importlib import metadata
from typing import Mapping

from corl._version import __version__  # the distribution is corl-skills: PyPI's "corl" is another project

__all__ = ["library_versions", "version_differences"]

# Packages whose version is always recorded ("not installed" when missing), then optional ones
# recorded only when installed.
_REQUIRED = ("numpy", "scipy", "cma", "joblib")
_OPTIONAL = ("mujoco",)
NOT_INSTALLED = "not installed"


def _package_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _numpy_blas() -> str | None:
    """Name and version of the BLAS numpy was built with, e.g. "scipy-openblas 0.3.30"."""
    try:
        import numpy as np  # already imported by corl itself; cheap

        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return f"{blas['name']} {blas['version']}".strip()
    except Exception:  # the layout of numpy's build report is not a stable API
        return None


def library_versions() -> dict[str, str]:
    """Versions of Python, corl, its numeric dependencies and the platform.

    Returns
    -------
    dict with keys ``python``, ``corl``, ``numpy``, ``scipy``, ``cma``, ``joblib``, ``platform``,
    ``numpy_blas`` (when numpy reports it) and ``mujoco`` (only when installed). Every value is a
    string; a required package that is missing reads "not installed".
    """
    versions = {"python": platform.python_version(), "corl": __version__}
    for name in _REQUIRED:
        versions[name] = _package_version(name) or NOT_INSTALLED
    for name in _OPTIONAL:
        found = _package_version(name)
        if found is not None:
            versions[name] = found
    blas = _numpy_blas()
    if blas:
        versions["numpy_blas"] = blas
    versions["platform"] = platform.platform()
    return versions


def version_differences(recorded: Mapping[str, str], current: Mapping[str, str]) -> list[str]:
    """Human-readable differences between two :func:`library_versions` results.

    Only keys present in both are compared: an older record may lack a key a newer corl adds.

    Returns
    -------
    One line per key whose value differs, e.g. ``"numpy 2.3.5 -> 2.4.0"``; empty when equal.
    """
    shared = sorted(set(recorded) & set(current))
    return [f"{key} {recorded[key]} -> {current[key]}" for key in shared if recorded[key] != current[key]]
