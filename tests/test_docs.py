"""The documentation: the site builds with warnings as errors, every module has a docstring, and
every code block of the user guide (docs/guide/*.md) and of README.md runs as written.

A page's blocks run in order in a fresh folder that holds a link to ``examples/`` (the guide's
commands run "from the repository's root"): ```python blocks in one namespace per page,
```bash and ```sh blocks with ``bash -euo pipefail``, this interpreter's bin folder first on PATH.
Blocks in ``text``, ``console``, ``output``, ``json``, ``toml`` or ``yaml`` are not code; every
block names its language. An HTML comment on the line before a block changes how it runs:

* ``<!-- docs-test: skip REASON -->``: not run (a handful at most, each with its reason);
* ``<!-- docs-test: serve ARGS -->``: run while ``corl serve --store <tmp>/serve-<ARGS>.corl --port P ARGS``
  answers on a free port P (blocks with the same ARGS continue one run); ``http://127.0.0.1:8765`` in the block is replaced by its address.

A comment line right after a ``print(...)`` line of a python block is what that print writes: the
block must print a line equal to it (or to its text before ``": "``, where the comment goes on to
explain), so a page never promises an output the code does not give.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import os
import pkgutil
import re
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import pytest

import corl

ROOT = Path(__file__).resolve().parents[1]
GUIDE = sorted((ROOT / "docs" / "guide").glob("*.md"))
PAGES = [ROOT / "README.md", *GUIDE]
NOT_CODE = {"text", "console", "output", "json", "toml", "yaml"}
SHELL = {"bash", "sh"}
MAX_SKIPPED = 5  # over the README and the guide
SLOW_PAGES = {"own-robot.md"}  # > 10 s: a MuJoCo robot learns, and a video is rendered
BLOCK_TIMEOUT = 300  # s, one block
SERVE_URL = "http://127.0.0.1:8765"
FENCE = re.compile(r"^(?P<indent> *)(?P<fence>`{3,})(?P<lang>[^`\s]*)[^`]*$")
DIRECTIVE = re.compile(r"^\s*<!--\s*docs-test:\s*(?P<kind>\w+)\s*(?P<arg>.*?)\s*-->\s*$")


@dataclass
class Block:
    page: str
    line: int  # 1-based line of the opening fence
    lang: str
    code: str
    directive: str = ""  # "", "skip" or "serve"
    argument: str = ""

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown page, with the directive on the line before each."""
    lines = path.read_text().splitlines()
    found, i = [], 0
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if not opening:
            i += 1
            continue
        indent, fence = len(opening["indent"]), opening["fence"]
        end = i + 1
        while end < len(lines) and not re.match(rf"^ {{0,{indent}}}{fence}`*\s*$", lines[end]):
            end += 1
        code = "\n".join(line[min(indent, len(line) - len(line.lstrip(" "))):] for line in lines[i + 1:end])
        previous = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
        directive = DIRECTIVE.match(previous)
        found.append(Block(path.name if path.parent == ROOT else f"docs/guide/{path.name}", i + 1,
                           opening["lang"].lower(), code + "\n", directive["kind"] if directive else "",
                           directive["arg"] if directive else ""))
        i = end + 1
    return found


def _tail(text: str, lines: int = 40) -> str:
    return "\n".join((text or "").strip().splitlines()[-lines:])


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _environment(folder: Path) -> dict[str, str]:
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"),
               OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(folder), env.get("PYTHONPATH", "")) if p)
    return env


@contextlib.contextmanager
def _server(folder: Path, argument: str, env: dict[str, str]):
    """``corl serve`` on a free port until the block is done; yields its address."""
    port = _free_port()
    url = f"http://127.0.0.1:{port}"
    store = folder / ("serve-" + re.sub(r"[^A-Za-z0-9_.-]+", "_", argument) + ".corl")
    command = [str(Path(sys.executable).parent / "corl"), "serve", "--store", str(store),
               "--port", str(port), *argument.split()]
    log = folder / "serve.log"
    with open(log, "w") as out:
        process = subprocess.Popen(command, cwd=folder, env=env, stdout=out, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while True:
            if process.poll() is not None:
                pytest.fail(f"corl serve exited with {process.returncode}:\n{_tail(log.read_text())}")
            try:
                with urllib.request.urlopen(f"{url}/status", timeout=2) as answer:
                    if answer.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"corl serve did not answer {url}/status within 60 s:\n{_tail(log.read_text())}")
            time.sleep(0.2)
        yield url
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def promised_output(code: str) -> list[str]:
    """The comment lines right after a ``print(...)`` line: the lines the block promises to print."""
    lines = code.splitlines()
    return [after.strip()[2:].strip() for line, after in zip(lines, lines[1:])
            if line.lstrip().startswith("print(") and after.strip().startswith("# ")]


def _printed(promise: str, output: str) -> bool:
    printed = [line.strip() for line in output.splitlines()]
    return any(promise == line or promise.startswith(line + ": ") for line in printed if line)


def _run_python(block: Block, code: str, namespace: dict) -> None:
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, block.where, "exec"), namespace)
    except Exception as exc:
        pytest.fail(f"{block.where}: the python block raised {type(exc).__name__}: {exc}\n"
                    f"output:\n{_tail(out.getvalue())}")
    for promise in promised_output(code):
        assert _printed(promise, out.getvalue()), \
            f"{block.where}: the page promises the output {promise!r}; the block printed:\n{_tail(out.getvalue())}"


def _run_shell(block: Block, code: str, folder: Path, env: dict[str, str]) -> None:
    try:
        done = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=folder, env=env,
                              capture_output=True, text=True, timeout=BLOCK_TIMEOUT)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{block.where}: the {block.lang} block ran longer than {BLOCK_TIMEOUT} s")
    if done.returncode != 0:
        pytest.fail(f"{block.where}: the {block.lang} block exited with {done.returncode}\n"
                    f"stdout:\n{_tail(done.stdout)}\nstderr:\n{_tail(done.stderr)}")


def _page_id(page: Path) -> str:
    return page.name if page.parent == ROOT else f"guide/{page.name}"


@pytest.mark.timeout(900)
@pytest.mark.parametrize("page", [pytest.param(p, id=_page_id(p), marks=[pytest.mark.slow] if p.name in SLOW_PAGES else [])
                                  for p in PAGES])
def test_every_code_block_of_the_page_runs(page, tmp_path, monkeypatch):
    (tmp_path / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    env = _environment(tmp_path)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("MUJOCO_GL", "OPENBLAS_NUM_THREADS"):
        monkeypatch.setenv(name, env[name])
    namespace: dict = {"__name__": "__main__"}
    for block in blocks(page):
        assert block.lang, f"{block.where}: name the block's language (python, bash, text, ...)"
        if block.directive == "skip" or block.lang in NOT_CODE:
            continue
        assert block.lang in SHELL | {"python"}, f"{block.where}: unknown language {block.lang!r}"
        with contextlib.ExitStack() as stack:
            code = block.code
            if block.directive == "serve":
                url = stack.enter_context(_server(tmp_path, block.argument, env))
                code = code.replace(SERVE_URL, url)
            else:
                assert block.directive == "", f"{block.where}: unknown directive {block.directive!r}"
            if block.lang == "python":
                _run_python(block, code, namespace)
            else:
                _run_shell(block, code, tmp_path, env)


def test_a_promised_output_is_read_and_checked():
    code = "x = 1\nprint(x, 2.0)\n# 1 2.0: one and two\nprint(x)  # a remark, not an output\ny = 2\n"
    assert promised_output(code) == ["1 2.0: one and two"]
    assert _printed("1 2.0: one and two", "1 2.0\n") and _printed("1 2.0", "0\n1 2.0\n")
    assert not _printed("[-0.0001] 1.00000", "[-9.20388473e-05] 0.9999999576442532\n")


def test_skipped_blocks_say_why_and_are_few():
    skipped = [b for page in PAGES for b in blocks(page) if b.directive == "skip"]
    assert all(b.argument for b in skipped), [b.where for b in skipped if not b.argument]
    assert len(skipped) <= MAX_SKIPPED, [b.where for b in skipped]
    unnamed = [b.where for page in PAGES for b in blocks(page) if not b.lang]
    assert unnamed == []


def test_the_readme_is_a_front_page_that_opens_with_the_two_commands():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    first = blocks(ROOT / "README.md")[0]
    commands = [line.split("#")[0].strip() for line in first.code.splitlines() if line.strip()]
    assert commands == ["make demo", "make test"]
    before = text[:text.index("```")]
    assert before.count("\n") <= 4, "the two commands come first"


def test_the_site_builds_with_warnings_as_errors(tmp_path):
    try:
        importlib.import_module("mkdocs")
        importlib.import_module("mkdocstrings_handlers.python")
        importlib.import_module("material")
    except ImportError as exc:
        if os.environ.get("CI"):
            pytest.fail(f"the docs extra is not installed ({exc}): pip install -e '.[docs]'")
        pytest.skip(f"the docs extra is not installed ({exc})")
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
                           "-d", str(site)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{_tail(done.stdout + done.stderr, 60)}"
    for page in ("index.html", "guide/own-task.html", "guide/own-robot.html", "guide/safe-bo.html",
                 "guide/server.html", "guide/contexts.html", "reproduction/door.html", "reference/problem.html"):
        assert (site / page).is_file(), page
    problem = (site / "reference" / "problem.html").read_text()
    assert "Outcome" in problem and "Demonstration" in problem
    assert "fonts.googleapis.com" not in (site / "index.html").read_text()  # the site works offline
    missing = []  # links to a heading or an API entry of another page: mkdocs checks the page, not the anchor
    for md in (ROOT / "docs").rglob("*.md"):
        for page, anchor in re.findall(r"\]\(([^)\s#]+\.md)#([^)\s]+)\)", md.read_text()):
            html = site / (md.parent / page).resolve().relative_to(ROOT / "docs").with_suffix(".html")
            if f'id="{anchor}"' not in html.read_text():
                missing.append(f"{md.relative_to(ROOT)}: {page}#{anchor}")
    assert missing == []


def test_every_module_imports_and_has_a_docstring():
    names = [m.name for m in pkgutil.walk_packages(corl.__path__, "corl.")]
    assert len(names) > 50 and "corl.store.sqlite" in names and "corl.tasks.door.sim" in names
    undocumented = [n for n in ["corl", *names] if not (importlib.import_module(n).__doc__ or "").strip()]
    assert undocumented == []
