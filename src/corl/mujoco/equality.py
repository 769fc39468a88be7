"""Joint equalities that compile the same under every MuJoCo in corl's range.

A joint equality holds ``q1 = c0 + c1 q2 + c2 q2^2 + c3 q2^3 + c4 q2^4`` (``q2`` absent: ``q1 = c0``).
Its coefficients live in the first five entries of ``MjsEquality.data``, whose length changed
(11 entries in mujoco 3.3, 12 from 3.17 on): passing ``data=[...]`` of one length fails under the
other, so corl writes the coefficients into the spec's own array instead.
"""

from __future__ import annotations

from typing import Sequence

__all__ = ["add_joint_equality"]


def add_joint_equality(spec, joint1: str, joint2: str | None = None, *, polycoef: Sequence[float] = (0.0, 1.0),
                       name: str | None = None, **attrs):
    """Add ``joint1 = poly(joint2)`` to ``spec`` (a :class:`mujoco.MjSpec`) and return the equality.

    Parameters
    ----------
    joint1, joint2 : joint names; without ``joint2`` the equality pins ``joint1`` at ``polycoef[0]``.
    polycoef : up to five coefficients ``c0..c4`` (default ``(0, 1)``: ``joint1 = joint2``); the
        rest are zero.
    name : the equality's name (e.g. to switch it off through ``data.eq_active``).
    attrs : other attributes of the equality (``solref``, ``solimp``, ``active``, ...).
    """
    import mujoco

    from corl.errors import InputError

    coef = [float(c) for c in polycoef]
    if not 1 <= len(coef) <= 5:
        raise InputError(f"polycoef holds 1 to 5 coefficients (c0..c4 of q1 = poly(q2)), got {len(coef)}")
    names = {j.name for j in spec.joints}
    for joint in (joint1, joint2):
        if joint is not None and joint not in names:
            raise InputError(f"no joint {joint!r} in the spec for the equality {name or ''}; its joints are "
                             f"{sorted(names)}")
    kw = {"type": mujoco.mjtEq.mjEQ_JOINT, "name1": joint1, **attrs}
    if joint2 is not None:
        kw["name2"] = joint2
    if name is not None:
        kw["name"] = name
    eq = spec.add_equality(**kw)
    data = eq.data  # a copy in some versions: write it back whole
    data[:] = 0.0
    data[:len(coef)] = coef
    eq.data = data
    return eq
