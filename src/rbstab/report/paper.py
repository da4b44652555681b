"""The paper's printed results (section 6) and their comparison with our runs.

The printed final states cannot be reproduced by the consistent equations (typos in B
and eq 21, missing case-2 gains; ``docs/physics.md``, section "The paper's printed
results"). The report shows them beside ours with the difference; nothing is ever tuned
to match them.

A run is a paper case when its ``name`` attribute *and* its variant are those of
:data:`PAPER_CASES` (``case1_permanent``/``permanent``, ``case2_visco_elastic``/
``visco_elastic``, ``case3_embedded``/``embedded``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..layout import OUTPUTS
from .load import RunData

__all__ = [
    "PrintedCase",
    "PAPER_CASES",
    "PAPER_DOCS",
    "PAPER_TIME",
    "PaperComparison",
    "paper_case",
    "compare_with_paper",
    "signed_peak",
]

#: Where the difference between our numbers and the printed ones is explained.
PAPER_DOCS = "docs/physics.md, section \"The paper's printed results\""
#: Time of the printed final states [s].
PAPER_TIME = 2.0


@dataclass(frozen=True)
class PrintedCase:
    """What section 6 of the paper prints for one case.

    Attributes
    ----------
    key : str
        The run name that identifies the case (``name`` attribute of the result file).
    variant : str
        The controller variant the case uses.
    title : str
        Section title in the paper.
    final : dict of str -> tuple of 3 floats
        Printed final state at t = 2 s per state block (``theta`` [rad], ``omega``
        [rad/s], ``position`` [m], ``velocity`` [m/s]).
    initial_constraint_violation : tuple of 3 floats or None
        "at the beginning of motion, all three constraints are violated by about -5, 2
        and 2 centimeters" [m], where printed.
    claim : str
        What the paper says in words.
    """

    key: str
    variant: str
    title: str
    final: dict = field(default_factory=dict)
    initial_constraint_violation: tuple | None = None
    claim: str = ""


#: The three cases of section 6, keyed by run name.
PAPER_CASES: dict[str, PrintedCase] = {
    "case1_permanent": PrintedCase(
        "case1_permanent",
        "permanent",
        "6.1 Case 1, Permanently Constrained System (eq 21, Fig 3)",
        final={"theta": (0.092, -0.1221, 0.0003), "omega": (0.0359, 0.0215, -0.0099)},
        claim="final state at t = 2.00 s: [0.092, -0.1221, 0.0003, 0.0359, 0.0215, -0.0099]",
    ),
    "case2_visco_elastic": PrintedCase(
        "case2_visco_elastic",
        "visco_elastic",
        "6.2 Case 2, Imposition of Constraint (eq 40, Figs 4, 5)",
        final={
            "position": (0.0015, -0.0024, -0.004),
            "velocity": (-0.100, 0.0007, 0.0000),
            "theta": (0.0057, 0.0035, 0.0000),
            "omega": (-0.0014, -0.0240, 0.0001),
        },
        initial_constraint_violation=(-0.05, 0.02, 0.02),
        claim="at the beginning of motion, all three constraints are violated by about -5, 2 and "
        "2 centimeters; the system is stable and the constraints are maintained",
    ),
    "case3_embedded": PrintedCase(
        "case3_embedded",
        "embedded",
        "6.3 Case 3, Embedded Constrained Rigid Body (eq 22, Figs 6, 7)",
        claim="no numbers printed; relative improvement in the maximum excursion of the "
        "constraints (E) over case 2",
    ),
}


def paper_case(run: RunData) -> PrintedCase | None:
    """The paper case ``run`` reproduces (name and variant both match), or None."""
    case = PAPER_CASES.get(run.name)
    return case if case is not None and case.variant == run.variant else None


def signed_peak(time: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per component, the value with the largest magnitude and when it occurs.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    values : ndarray, shape (n, 3)
        E.g. the constraint error E [m]; NaN rows are ignored.

    Returns
    -------
    peak : ndarray, shape (3,)
        ``values[i_k, k]`` with ``i_k = argmax |values[:, k]|`` (sign kept).
    at : ndarray, shape (3,)
        ``time[i_k]`` [s].
    """
    filled = np.where(np.isfinite(values), np.abs(values), -np.inf)
    idx = np.argmax(filled, axis=0)
    return values[idx, np.arange(values.shape[1])], time[idx]


@dataclass
class PaperComparison:
    """Our run beside the printed numbers of one paper case.

    Attributes
    ----------
    case : PrintedCase
    run : RunData
    rows : list of dict
        One per printed component: ``quantity`` (e.g. ``"Theta_1"``), ``units``,
        ``printed``, ``ours`` and ``difference`` (= ours - printed).
    notes : list of str
        Caveats (a run that does not end at t = 2 s, a failed run, overrides on the
        command line, the case-3 claim checked against case 2).
    """

    case: PrintedCase
    run: RunData
    rows: list = field(default_factory=list)
    notes: list = field(default_factory=list)


def compare_with_paper(runs: Sequence[RunData]) -> list[PaperComparison]:
    """Compare every paper case among ``runs`` with the printed numbers.

    Our values are the summary attributes ``final_<block>`` (the state at the last
    finite sample, ``t_final``) and, for the printed initial constraint violation of
    case 2, :func:`signed_peak` of the stored ``constraint_error``.

    Returns
    -------
    list of PaperComparison
        In the order of ``runs``; empty when no run is a paper case.
    """
    found = [(run, paper_case(run)) for run in runs]
    found = [(run, case) for run, case in found if case is not None]
    out = []
    for run, case in found:
        comp = PaperComparison(case, run)
        for block, printed in case.final.items():
            ours = run.summary.get(f"final_{block}")
            ours = [float("nan")] * 3 if ours is None else [float(v) for v in ours]
            for i in range(3):
                comp.rows.append(
                    {
                        "quantity": f"{OUTPUTS[block].symbol}_{i + 1} at t_end",
                        "units": OUTPUTS[block].display_units,
                        "printed": printed[i],
                        "ours": ours[i],
                        "difference": ours[i] - printed[i],
                    }
                )
        if case.initial_constraint_violation is not None:
            s = run.series("constraint_error")
            peak, at = signed_peak(s["time"], s["constraint_error"])
            e = OUTPUTS["constraint_error"]
            for i in range(3):
                comp.rows.append(
                    {
                        "quantity": f"{e.symbol}_{i + 1}, largest excursion (at t = {at[i]:.3g} s)",
                        "units": e.display_units,
                        "printed": case.initial_constraint_violation[i],
                        "ours": float(peak[i]),
                        "difference": float(peak[i]) - case.initial_constraint_violation[i],
                    }
                )
        t_final = float(run.summary.get("t_final", np.nan))
        if not run.ok:
            comp.notes.append(f"the run failed at t = {t_final:g} s ({run.message}); its final state is not comparable")
        elif case.final and not np.isclose(t_final, PAPER_TIME):
            comp.notes.append(
                f"this run ends at t = {t_final:g} s, the printed values are at t = {PAPER_TIME:g} s: "
                "the comparison is not like for like"
            )
        command = str(run.attrs.get("command_line", ""))
        if "--set" in command or "--method" in command:
            comp.notes.append(f"the run was made with overrides: {command}")
        if case.key == "case3_embedded":
            comp.notes.extend(_case3_claim(run, [r for r, c in found if c.key == "case2_visco_elastic"]))
        out.append(comp)
    return out


def _case3_claim(run3: RunData, runs2: Sequence[RunData]) -> list[str]:
    """The paper's case-3 claim (smaller constraint excursion than case 2), checked."""
    if not runs2:
        return ["include the case-2 run to check the claim of a smaller constraint excursion than case 2"]
    notes = []
    e3 = np.asarray(run3.summary.get("max_abs_constraint_error", [np.nan] * 3), float)
    for run2 in runs2:
        e2 = np.asarray(run2.summary.get("max_abs_constraint_error", [np.nan] * 3), float)
        smaller = [f"E_{i + 1}" for i in range(3) if e3[i] < e2[i]]
        larger = [f"E_{i + 1}" for i in range(3) if e3[i] >= e2[i]]
        verdict = "holds on every axis" if not larger else (
            "does not hold on any axis" if not smaller else f"holds on {', '.join(smaller)}, not on {', '.join(larger)}"
        )
        ratio = ", ".join(f"{a / b:.3g}" if b else "-" for a, b in zip(e3, e2))
        note = (
            f"claim 'smaller constraint excursion than case 2' against {run2.label}: {verdict} "
            f"(max |E| of {run3.label} / {run2.label} per axis: {ratio})"
        )
        k3, k2 = run3.flat_config.get("controller.k_c"), run2.flat_config.get("controller.k_c")
        try:
            stiffer = np.asarray(k3, float) / np.asarray(k2, float)
        except (TypeError, ValueError):
            stiffer = None
        if stiffer is not None and stiffer.shape and np.all(np.isfinite(stiffer)) and not np.allclose(stiffer, 1.0):
            note += (
                f". The two runs also differ in K_c ({run3.label} / {run2.label}: "
                + ", ".join(f"{r:.3g}" for r in np.ravel(stiffer))
                + "), so the difference is not the controller state D alone (see docs/physics.md)"
            )
        notes.append(note)
    return notes
