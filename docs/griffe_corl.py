"""Griffe extension for the API reference (mkdocs.yml): read corl's docstring entries as written.

corl's NumPy docstrings write an entry on one line, ``name : what it is``, with shapes in the
text (``theta : (m,) the point to realise``), rather than NumPy's ``name : type`` line followed by
an indented description. Griffe's NumPy parser reads the text after the colon as a type, so the
reference would show every description in the type column. After the package is loaded, this
moves such text into the description (a short word such as ``float`` or ``Realisation`` stays a
type), and splits ``Returns`` and ``Raises`` entries written ``Type : what``. Sphinx roles
(``:func:`name```) become code, a glossary's ``symbol : meaning`` lines a list, and a paragraph
that ends in ``::`` before an indented block ends in ``:``.
"""

from __future__ import annotations

import re
from functools import cached_property
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|const|ref):`~?\.?([^`]+)`")
_ENTRY = re.compile(r"^(\S[^:]*?) : (.*)$")


def _text(annotation: Any) -> str:
    return "" if annotation is None else str(annotation)


def _is_type(text: str) -> bool:
    """A type written in a docstring (``float``, ``np.ndarray``, ``Bounds | None``), not a sentence."""
    return bool(text) and " : " not in text and len(text.replace(" | ", "|").replace(", ", ",").split()) == 1


def _join(first: str, rest: str) -> str:
    return f"{first}\n{rest}" if first and rest else first or rest


def _markdown(text: str) -> str:
    text = _ROLE.sub(lambda m: f"``{m.group(1)}``", text)
    return re.sub(r"(?<=\S)::$", ":", text, flags=re.MULTILINE)


def _entries_as_list(text: str) -> str:
    """``symbol : meaning`` lines (and their indented continuations) as a Markdown list."""
    lines = []
    for line in text.splitlines():
        entry = _ENTRY.match(line)
        if entry:
            lines.append(f"- **{entry.group(1).strip()}**: {entry.group(2)}")
        elif line.startswith(" ") and lines and lines[-1].startswith(("- ", "  ")):
            lines.append("  " + line.strip())
        else:
            lines.append(line)
    return "\n".join(lines)


def _fix_item(kind: str, item: Any) -> None:
    text = _text(item.annotation)
    if kind in ("returns", "yields", "receives", "raises", "warns") and " : " in text:
        head, tail = text.split(" : ", 1)  # "Type : what it is" on one line
        item.annotation, item.description = head.strip(), _join(tail.strip(), item.description)
    elif text and not _is_type(text):
        item.annotation, item.description = None, _join(text, item.description)


def _fix_sections(sections: list) -> list:
    for section in sections:
        value = section.value
        if isinstance(value, str):
            section.value = _markdown(value)
        elif isinstance(value, list):
            for item in value:
                if hasattr(item, "annotation") and hasattr(item, "description"):
                    _fix_item(section.kind.value, item)
                    item.description = _markdown(item.description)
        elif hasattr(value, "contents"):  # an admonition, e.g. a module's "Glossary" section
            value.contents = _entries_as_list(_markdown(value.contents))
    return sections


class _CorlDocstring(griffe.Docstring):
    """A docstring whose sections are read as above when first rendered (parsing stays lazy:
    only the objects the reference shows are parsed, as without this extension)."""

    @cached_property
    def parsed(self) -> list:
        return _fix_sections(griffe.Docstring.parsed.func(self))


def _walk(obj: griffe.Object, seen: set[int]) -> None:
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if obj.docstring is not None and type(obj.docstring) is griffe.Docstring:
        obj.docstring.__class__ = _CorlDocstring
    for member in obj.members.values():
        if not member.is_alias:
            _walk(member, seen)


class CorlDocstrings(griffe.Extension):
    """Rewrite the parsed docstrings of a loaded package once (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__()
        self._done: set[int] = set()

    def _fix(self, pkg: griffe.Module) -> None:
        if id(pkg) not in self._done:
            self._done.add(id(pkg))
            _walk(pkg, set())

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:  # griffe >= 1.14
        self._fix(pkg)

    def on_package_loaded(self, *, pkg: griffe.Module, **kwargs: Any) -> None:  # older griffe
        self._fix(pkg)
