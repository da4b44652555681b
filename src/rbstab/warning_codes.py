"""The codes of rbstab's warnings: one registry.

A warning is something rbstab goes on with but the user should know. Each kind has a code,
and its message starts with it, wherever the message goes: a Python warning (emitted with
its category when a config is loaded), ``RunConfig.warnings``, the digest of a sweep, the
notes of an analysis. For example::

    W001 body.inertia: principal moments (10, 8, 0.4) kg m^2 violate the triangle
    inequality (j1 = 10 > 8 + 0.4); no real body has them

The command line shows each warning once per command, as one line on stderr (with ``-v``
followed by the explanation below), and ``--no-warn CODE`` (repeatable; ``--no-warn all``)
silences it. From Python::

    import warnings
    warnings.filterwarnings("ignore", message=r".*\\bW001\\b")   # or by category:
    warnings.filterwarnings("ignore", category=rbstab.config.PhysicalPlausibilityWarning)

The README's "Warnings" section lists the same codes (a test keeps the two in step).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["WarningCode", "WARNING_CODES", "coded", "code_of", "split_code"]


@dataclass(frozen=True)
class WarningCode:
    """One kind of warning.

    Attributes
    ----------
    code : str
        ``W`` and three digits.
    subject : str
        What it is about (a config key, or the part of rbstab).
    title : str
        One line: what it means.
    explanation : str
        What to do about it (shown by ``-v``).
    """

    code: str
    subject: str
    title: str
    explanation: str


#: Every warning rbstab gives, by code.
WARNING_CODES: dict[str, WarningCode] = {
    w.code: w
    for w in (
        WarningCode(
            "W001", "body.inertia", "the inertia violates the triangle inequality j_i <= j_k + j_l",
            "every real rigid body satisfies it; the equations of motion still hold, so rbstab runs it "
            "(the paper's Table 1 inertia (10, 8, 0.4) is such a case, see docs/physics.md)",
        ),
        WarningCode(
            "W002", "controller.<gain>", "a gain v needs definite is positive semi-definite, not definite",
            "valid physics (a torque-free body, a passive pendulum), but v is then not a strict Lyapunov "
            "function and asymptotic stability is not implied (docs/physics.md)",
        ),
        WarningCode(
            "W003", "simulation.n_samples", "a run holds a large amount of memory",
            "it fits in the memory available; lower simulation.n_samples to make it smaller",
        ),
        WarningCode(
            "W004", "rbstab sweep", "result files in the sweep's runs/ folder are not runs of its spec",
            "left in place and not in the index: runs of an earlier version of the spec, or files copied "
            "there; remove them, or sweep into another folder (-o)",
        ),
        WarningCode(
            "W005", "initial_state.theta", "an initial Euler angle beyond 2 pi rad (degrees typed as radians?)",
            "angles are in radians: 45 rad is more than seven turns; write 0.785 for 45 degrees "
            "(the run goes on with the value as given)",
        ),
        WarningCode(
            "W007", "joints", "with gravity, bodies that nothing holds fall without bound",
            "no joint ties them to the ground (their joints are free) and their ground-anchored feedback "
            "(bodies' k_t) leaves a direction in which their weight pulls: they fall without end, v has no "
            "minimum and the run's v means nothing; give them a joint to the ground or a k_t",
        ),
        WarningCode(
            "W009", "simulation.limits", "a body under gravity without an admissible region",
            "a run that falls is not stopped: it swings on (through the ground) and reads as still settling or "
            "moving away, or swings back and counts as recovered; set simulation.limits (theta, position) where "
            "a fall begins, and the run then reads 'fell' (docs/physics.md)",
        ),
        WarningCode(
            "W006", "rbstab tune", "a tuned value lies within 1 % of its search range's edge",
            "the optimum may lie beyond the range searched: widen that --vary range and tune again",
        ),
        WarningCode(
            "W008", "simulation.method", "a stiff mode holds the explicit method to very many steps",
            "the fastest mode of the linearisation at rest bounds an explicit method's step to its stability "
            "limit (h |s| <= 2.5 RK23, 3.3 RK45, 6.4 DOP853) whatever the tolerances; an implicit method "
            "(Radau, BDF, LSODA) is held only to the accuracy they ask, far fewer steps once that mode has died "
            "out (while the motion excites it, every method follows it; a mode the motion never excites, out "
            "of the plane of a planar swing, does not hold the explicit method back). Or is the gain meant to "
            "be this stiff? (docs/performance.md)",
        ),
    )
}

_CODE = re.compile(r"\b(W\d{3})\b")


def coded(code: str, text: str) -> str:
    """``"<code> <text>"``: a warning message with its code (which must be registered)."""
    if code not in WARNING_CODES:
        raise KeyError(f"unregistered warning code {code!r}")
    return f"{code} {text}"


def code_of(text: str) -> str | None:
    """The first registered code in ``text``, or None."""
    for match in _CODE.finditer(text):
        if match.group(1) in WARNING_CODES:
            return match.group(1)
    return None


def split_code(text: str) -> tuple[str | None, str, str]:
    """``(code, before, message)``: ``text`` cut at its code, e.g.
    ``"case1.yaml: W001 body.inertia: ..."`` -> ``("W001", "case1.yaml: ", "W001 body.inertia: ...")``;
    ``(None, "", text)`` without one."""
    code = code_of(text)
    if code is None:
        return None, "", text
    at = text.index(code)
    return code, text[:at], text[at:]
