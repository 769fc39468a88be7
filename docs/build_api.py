"""Write the API reference of ``corl`` as HTML with pdoc: one page per module (``make docs``).

    python docs/build_api.py [OUT]          # default OUT: docs/api

pdoc follows a package's ``__all__`` and so skips the submodules a package does not re-export
(``corl.gp.kernels``, ``corl.store.sqlite``, ...); they are named here explicitly, so that every
module of the package gets its page. Docstrings are NumPy style.
"""

from __future__ import annotations

import pkgutil
import sys
import warnings
from pathlib import Path


def module_names(package: str = "corl") -> list[str]:
    """``package`` and every module below it, in import order of :func:`pkgutil.walk_packages`."""
    root = __import__(package)
    return [package] + [m.name for m in pkgutil.walk_packages(root.__path__, f"{package}.")]


def specs(package: str = "corl") -> list[str]:
    """What to hand to pdoc: the package, plus each module its ``__all__`` walk would miss."""
    from pdoc.extract import walk_specs

    reached = set(walk_specs([package]))
    return [package] + [name for name in module_names(package) if name not in reached]


def build(out: Path, modules: list[str] | None = None) -> list[Path]:
    """Render ``modules`` (default: all of corl) into ``out``; returns the HTML files written."""
    import pdoc
    import pdoc.render

    pdoc.render.configure(docformat="numpy", search=True, show_source=True)
    # A NamedTuple's generated __new__ has no module globals, so pdoc cannot evaluate string
    # annotations such as 'np.ndarray' on it; the page shows them as written, which is fine.
    warnings.filterwarnings("ignore", message=r"Error parsing type annotation .*__init__\. Import of np failed")
    pdoc.pdoc(*(modules or specs()), output_directory=out)
    return sorted(out.rglob("*.html"))


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent / "api"
    pages = build(target)
    print(f"wrote {len(pages)} pages to {target} (open {target / 'index.html'})")
