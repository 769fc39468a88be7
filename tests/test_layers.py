"""The house rules (tools/check_layers.py): imports point down, no import cycles, no file over 500 lines."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tools" / "check_layers.py"


def _check(package: Path | None = None) -> subprocess.CompletedProcess:
    args = [sys.executable, str(SCRIPT)] + ([str(package)] if package is not None else [])
    return subprocess.run(args, capture_output=True, text=True, cwd=ROOT, timeout=60)


def _write(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    return root / "corl"


def test_the_package_keeps_the_house_rules():
    result = _check()
    assert result.returncode == 0, "tools/check_layers.py found violations:\n" + result.stdout + result.stderr
    assert result.stdout.startswith("ok: ") and result.stdout.count("\n") == 1


def test_a_clean_package_passes(tmp_path):
    package = _write(tmp_path, {
        "corl/__init__.py": '"""top"""\n',
        "corl/errors.py": "class CorlError(Exception):\n    pass\n",
        "corl/problem.py": "from corl.errors import CorlError\n",
        "corl/tasks/__init__.py": "from corl.tasks.synthetic import make\n",
        "corl/tasks/synthetic.py": "from . import registry\n\ndef make():\n    from corl.problem import CorlError\n",
        "corl/tasks/registry.py": "import numpy\n",
        "corl/cli/__init__.py": "from corl.cli import run\n",
        "corl/cli/run.py": "def run():\n    from corl.tasks import make\n",
    })
    result = _check(package)
    assert result.returncode == 0, result.stdout
    assert re.fullmatch(r"ok: 8 modules in \d+ layers, imports point down, no cycles, no file over 500 lines\n",
                        result.stdout)


def test_an_upward_import_a_cycle_a_long_file_and_an_undeclared_module_are_flagged(tmp_path):
    package = _write(tmp_path, {
        "corl/__init__.py": '"""top"""\n',
        # upward, and inside a function: the solvers' layer reaching into the experiments
        "corl/trajectory/__init__.py": "",
        "corl/trajectory/solver.py": "import math\n\n\ndef solve():\n    from corl.experiments.methods import make\n",
        "corl/experiments/__init__.py": "",
        "corl/experiments/methods.py": "def make():\n    pass\n",
        # a circle inside one layer, closed by a relative import inside a function
        "corl/tasks/__init__.py": "",
        "corl/tasks/a.py": "from corl.tasks import b\n",
        "corl/tasks/b.py": "def f():\n    from . import a\n",
        "corl/tasks/long.py": "x = 1\n" * 501,
        "corl/elsewhere.py": "",
        "corl/cli.py": "import corl.tasks.gone\n",
    })
    result = _check(package)
    assert result.returncode == 1
    lines = result.stdout.splitlines()
    assert len(lines) == 5, result.stdout
    upward = [line for line in lines if "upward import" in line]
    assert len(upward) == 1 and upward[0].endswith(
        "solver.py:5: upward import: corl.trajectory.solver (trajectory) imports corl.experiments.methods "
        "(experiments), a higher layer")
    cycles = [line for line in lines if "import cycle" in line]
    assert len(cycles) == 1 and "corl.tasks.a -> corl.tasks.b -> corl.tasks.a" in cycles[0]
    assert "corl.tasks.b -> corl.tasks.a at line 2" in cycles[0]
    assert any(line.endswith("long.py:501: long file: 501 lines, more than 500") for line in lines)
    assert any("unassigned module: corl.elsewhere" in line for line in lines)
    assert any("unknown module: corl.cli imports corl.tasks.gone" in line for line in lines)


def test_a_circle_through_an_upward_import_is_reported_as_both(tmp_path):
    package = _write(tmp_path, {
        "corl/__init__.py": '"""top"""\n',
        "corl/session.py": "def build():\n    from corl.experiments import methods\n",
        "corl/experiments/__init__.py": "",
        "corl/experiments/methods.py": "import corl.session\n",
    })
    result = _check(package)
    assert result.returncode == 1
    lines = result.stdout.splitlines()
    assert [line.split(": ")[1] for line in lines] == ["upward import", "import cycle"], result.stdout
    assert "corl.experiments.methods -> corl.session -> corl.experiments.methods" in lines[1]


def test_not_a_package_is_a_clear_error(tmp_path):
    result = _check(tmp_path)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.startswith("error: ") and "no __init__.py" in result.stderr
