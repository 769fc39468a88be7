"""Read MJCF text and compile specs with MuJoCo's errors turned into one-line :class:`InputError` s.

MuJoCo reports a malformed file, a missing include or mesh, or a repeated name as a ``ValueError``
over several lines; the kit's loaders and builders call these helpers instead, so the user gets one
line that says what was wrong and what to do. MuJoCo is imported only when called.
"""

from __future__ import annotations

import os
from pathlib import Path

from corl.errors import InputError

__all__ = ["parse_mjcf", "compile_spec", "check_spec", "one_line"]


def one_line(exc: BaseException) -> str:
    """MuJoCo's (multi-line) message of ``exc`` on one line."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _hint(message: str, from_text: bool) -> str:
    """What to do about a MuJoCo error ``message``."""
    lower = message.lower()
    if "opening file" in lower or "resource not found" in lower or "could not open" in lower:
        if from_text:
            return "give the path of the XML file rather than its text, so relative files are found"
        return "check that the file exists where the XML says (relative to its folder, meshdir or assetdir)"
    if "repeated name" in lower:
        return "give every element of one kind a unique name"
    if "schema violation" in lower:
        import mujoco

        return f"fix the XML (a file saved by a newer MuJoCo may use what MuJoCo {mujoco.__version__} lacks)"
    return "fix the XML"


def parse_mjcf(source: str | os.PathLike, what: str = "MJCF"):
    """``mujoco.MjSpec`` of MJCF ``source``: XML text (a ``str`` starting with ``<``) or a file path.

    Raises
    ------
    InputError : one line naming MuJoCo's complaint (malformed XML, a missing include, ...).
    """
    import mujoco

    from_text = isinstance(source, str) and source.lstrip().startswith("<")
    try:
        if from_text:
            return mujoco.MjSpec.from_string(source)
        return mujoco.MjSpec.from_file(str(Path(source)))
    except ValueError as exc:
        message = one_line(exc)
        raise InputError(f"cannot read the {what}: {message}; {_hint(message, from_text)}") from None


def compile_spec(spec, what: str = "scene"):
    """``spec.compile()``, or an :class:`InputError` with MuJoCo's reason on one line."""
    import mujoco

    check_spec(spec, "compile_spec")
    try:
        return spec.compile()
    except ValueError as exc:
        message = one_line(exc)
        # a spec from text has no folder: a missing file there is about the path
        from_text = not getattr(spec, "modelfiledir", "")
        raise InputError(f"the {what} does not compile: {message}; {_hint(message, from_text)}") from None
    except mujoco.FatalError as exc:  # pragma: no cover - MuJoCo's own fatal errors
        raise InputError(f"the {what} does not compile: {one_line(exc)}") from None


def check_spec(spec, caller: str) -> None:
    """Refuse anything but a ``mujoco.MjSpec`` as ``spec`` of ``caller``."""
    import mujoco

    if not isinstance(spec, mujoco.MjSpec):
        raise InputError(f"{caller} needs a mujoco.MjSpec (from corl.mujoco.load_spec), got {type(spec).__name__}; "
                         "add servos and sensors before compiling it into a Robot")
