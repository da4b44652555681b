"""How a run of the compiled engine ended: its status codes and their messages.

As scipy's ``solve_ivp`` keeps a status -> message table beside its solvers, this module
is the one place that names the codes the compiled integrators return
(:mod:`rbstab.engine.integrate`, :mod:`rbstab.engine.switching`) and says what each
means; the codes are plain ints, which compiled code reads as constants.

======  ===================  ==========================================================
code    name                 the run ...
======  ===================  ==========================================================
0       ``SUCCESS``          reached t_end
1       ``GIMBAL_LOCK``      stopped at the gimbal-lock event (the event time returned)
-1      ``TOO_SMALL_STEP``   needed a step below the spacing of floats (scipy's failure)
-2      ``NOT_FINITE``       met a non-finite step size or state
-3      ``STEP_LIMIT``       took ``simulation.max_steps`` steps
-4      ``TIMEOUT``          ran past ``simulation.max_wall_time``
-5      ``SWITCHING_LIMIT``  located its largest number of switchings (pure sign law)
-6      ``NOT_STARTED``      was not started: its GPU launch had reached its wall-time limit
2-999   ``LEFT_REGION + k``  left the admissible region (``simulation.limits``): |q_i|
                             reached its bound (the event time returned), k = 15 b +
                             3 j + i for the quantity j of :data:`rbstab.layout.LIMITED`,
                             the axis i and body (or joint) b of a tree, 0 for one body
                             (:func:`limit_status`, :func:`limit_of`, :func:`limit_part`)
>=1000  ``TREE_GIMBAL + k``  a tree's gimbal lock (the event time returned): k = 2 b for
                             body b's Theta, 2 b + 1 for joint b's Theta_j
                             (:func:`gimbal_status`, :func:`gimbal_of`)
>=2000  ``RANGE_LEFT + k``   a joint's coordinate left the admissible region of its range
                             (the event time returned): k = 6 b + 2 i at its lower end,
                             6 b + 2 i + 1 at its upper end, of coordinate i (a hinge's q:
                             0; a ball's Euler angles: 0-2) of joint b (:func:`range_status`,
                             :func:`range_of`)
======  ===================  ==========================================================

A run whose code is not :data:`SUCCESS` has status ``"failed"``, with
:func:`status_message` as its message. Two kinds of failed run differ in what they mean
(:func:`fell`): a run that stopped at gimbal lock or where it left the admissible region
*fell*: its motion was computed up to the event, which is a result of its physics; every
other failed run (a solver failure, a non-finite state, a step, wall-time or switching
limit, a launch that did not start) *could not be computed*.
"""

from __future__ import annotations

import math

from ..layout import LIMITED, LIMITED_COMPONENTS, OUTPUTS, display_units

__all__ = [
    "SUCCESS",
    "GIMBAL_LOCK",
    "TOO_SMALL_STEP",
    "NOT_FINITE",
    "STEP_LIMIT",
    "TIMEOUT",
    "SWITCHING_LIMIT",
    "NOT_STARTED",
    "LEFT_REGION",
    "limit_status",
    "limit_of",
    "limit_part",
    "TREE_GIMBAL",
    "gimbal_status",
    "gimbal_of",
    "RANGE_LEFT",
    "range_status",
    "range_of",
    "PART_CODES",
    "STATUSES",
    "SUCCESS_MESSAGE",
    "TOO_SMALL_STEP_MESSAGE",
    "DEFAULT_MAX_STEPS",
    "status_message",
    "FALL_MESSAGES",
    "fell",
    "fell_mask",
    "computed",
]

SUCCESS, GIMBAL_LOCK, TOO_SMALL_STEP, NOT_FINITE, STEP_LIMIT, TIMEOUT, SWITCHING_LIMIT, NOT_STARTED = (
    0, 1, -1, -2, -3, -4, -5, -6)

#: The first code of a run that left the admissible region: LEFT_REGION + PART_CODES b +
#: 3 j + i for the bound of quantity j (:data:`rbstab.layout.LIMITED`) on axis i, reached
#: by body (or joint) b of a tree (0 for one body).
LEFT_REGION = 2
#: The region's codes of each body or joint: an axis of each quantity of :data:`rbstab.layout.LIMITED`.
PART_CODES = 3 * len(LIMITED)


def limit_status(quantity: int, axis: int, part: int = 0) -> int:
    """The status code of a run whose |q_i| reached its bound: q the ``quantity``-th of
    :data:`rbstab.layout.LIMITED`, i = ``axis`` (0, 1, 2), of body (or, for E, joint)
    ``part`` of a tree (0 for one body)."""
    return LEFT_REGION + PART_CODES * part + 3 * quantity + axis


def limit_of(status: int) -> tuple[str, int] | None:
    """(the bounded quantity's name in :data:`rbstab.layout.LIMITED`, the axis 0-2) of a
    status code of :func:`limit_status`, or None for another code."""
    k = int(status) - LEFT_REGION
    return (LIMITED[k % PART_CODES // 3], k % 3) if 0 <= k < TREE_GIMBAL - LEFT_REGION else None


def limit_part(status: int) -> int:
    """The body (or, for E, joint) of a tree whose bound a status code of
    :func:`limit_status` names (0 for one body)."""
    return (int(status) - LEFT_REGION) // PART_CODES


#: The first code of a tree's gimbal lock, after every code of the admissible region.
TREE_GIMBAL = 1000


def gimbal_status(part: int, joint: bool) -> int:
    """The status code of a tree's run stopped where |theta_2| reached pi/2 - gimbal_margin:
    of body ``part``'s Theta, or with ``joint`` of joint ``part``'s relative Theta_j (the
    joint whose child is body ``part``)."""
    return TREE_GIMBAL + 2 * part + int(joint)


def gimbal_of(status: int) -> tuple[int, bool] | None:
    """(the part, whether it is the joint's Theta_j) of a status code of :func:`gimbal_status`,
    or None for another code."""
    k = int(status) - TREE_GIMBAL
    return (k // 2, bool(k % 2)) if 0 <= k < RANGE_LEFT - TREE_GIMBAL else None


#: The first code of a run whose joint's coordinate left the admissible region of its range,
#: after every code of a tree's gimbal lock.
RANGE_LEFT = 2000


def range_status(joint: int, coordinate: int, upper: bool) -> int:
    """The status code of a tree's run stopped where ``coordinate`` (a hinge's q: 0; a ball's
    Euler angles: 0-2) of joint ``joint`` reached the lower end of its range (an admissible
    region), or with ``upper`` its upper end."""
    return RANGE_LEFT + 6 * joint + 2 * coordinate + int(upper)


def range_of(status: int) -> tuple[int, int, bool] | None:
    """(the joint, its coordinate, whether it reached the upper end) of a status code of
    :func:`range_status`, or None for another code."""
    k = int(status) - RANGE_LEFT
    return (k // 6, k % 6 // 2, bool(k % 2)) if k >= 0 else None


#: Accepted steps after which a run stops as failed (a run that would never finish).
DEFAULT_MAX_STEPS = 10_000_000

#: scipy's ``solve_ivp`` message for a run that reached the end of its interval.
SUCCESS_MESSAGE = 'The solver successfully reached the end of the integration interval.'

#: scipy's ``OdeSolver.TOO_SMALL_STEP``: a step below 10 * spacing(t).
TOO_SMALL_STEP_MESSAGE = 'Required step size is less than spacing between numbers.'

#: code -> (name, message template); the template's fields are the keywords of
#: :func:`status_message`.
STATUSES: dict[int, tuple[str, str]] = {
    SUCCESS: ("SUCCESS", SUCCESS_MESSAGE),
    GIMBAL_LOCK: ("GIMBAL_LOCK", "gimbal lock: |theta_2| reached pi/2 - {gimbal_margin:g} rad at t = {t_stop:.6g} s; "
                                 "B(theta) is singular there (eq 5), so the Euler-angle model stops"),
    TOO_SMALL_STEP: ("TOO_SMALL_STEP", f"solver failed: {TOO_SMALL_STEP_MESSAGE} (at t = {{t_stop:.6g}} s)"),
    NOT_FINITE: ("NOT_FINITE", "non-finite step size or state at t = {t_stop:.6g} s"),
    STEP_LIMIT: ("STEP_LIMIT", "step limit: {max_steps} steps taken (simulation.max_steps), reaching only "
                               "t = {t_stop:.6g} s"),
    TIMEOUT: ("TIMEOUT", "timeout: the run exceeded {max_wall_time:g} s of wall time at t = {t_stop:.6g} s"),
    SWITCHING_LIMIT: ("SWITCHING_LIMIT", "switching limit: {max_switchings} events located by t = {t_stop:.6g} s "
                                         "(the switchings accumulate without reaching the resolution "
                                         "{resolution:g} m)"),
    NOT_STARTED: ("NOT_STARTED", "not run: its GPU launch reached its wall-time limit of {max_wall_time:g} s "
                                 "(simulation.max_wall_time) before the run started; run it again"),
    **{limit_status(j, i): (f"LEFT_REGION_{name.upper()}_{i}",
                            f"left the admissible region: |{LIMITED_COMPONENTS[name]}_{i + 1}| reached "
                            f"simulation.limits.{name} = {{bound:g}} {display_units(OUTPUTS[name].units)} at "
                            "t = {t_stop:.6g} s")
       for j, name in enumerate(LIMITED) for i in range(3)},
}


def status_message(status: int, t_stop: float, gimbal_margin: float, max_steps: int = DEFAULT_MAX_STEPS,
                   max_wall_time: float = math.inf, *, max_switchings: int = 0, resolution: float = 0.0,
                   limits=None) -> str:
    """The message of a run that ended with ``status`` (scipy's words where scipy has them).

    Parameters
    ----------
    status : int
        A code of :data:`STATUSES`.
    t_stop : float
        Where the run stopped [s] (the event time for gimbal lock).
    gimbal_margin : float
        ``simulation.gimbal_margin`` [rad].
    max_steps, max_wall_time : int, float
        The run's step limit and wall-time limit [s].
    max_switchings, resolution : int, float
        The pure sign law's limit of located switchings and its resolution [m].
    limits : array_like, shape (5, 3), optional
        The run's admissible region (the ``limits`` field of its
        :data:`rbstab.model.PARAMETERS` record, rows :data:`rbstab.layout.LIMITED`): the
        bound a run that left it reached.

    Raises
    ------
    KeyError
        For a code not in :data:`STATUSES`.
    """
    which = limit_of(status)
    bound = math.nan if which is None or limits is None else float(limits[LIMITED.index(which[0])][which[1]])
    return STATUSES[int(status)][1].format(
        t_stop=t_stop, gimbal_margin=gimbal_margin, max_steps=max_steps, max_wall_time=max_wall_time,
        max_switchings=max_switchings, resolution=resolution, bound=bound)


#: How the message of a run that fell begins (the codes :data:`GIMBAL_LOCK` and
#: ``LEFT_REGION + k``, for one body and for chains).
FALL_MESSAGES = ("gimbal lock", "left the admissible region")


def fell(status: str, message: str | None) -> bool:
    """Whether a run of ``status`` (``"success"``, ``"failed"``, ``"error"``, ``"pending"``)
    and ``message`` fell: it stopped at gimbal lock or where it left the admissible region,
    its motion computed up to there (a result of its physics, not a fault)."""
    return status == "failed" and isinstance(message, str) and message.startswith(FALL_MESSAGES)


def fell_mask(status, message) -> "np.ndarray":
    """:func:`fell` of many runs: ``status`` and ``message`` of shape (n,) (numpy arrays,
    pandas columns or lists; text, None or NaN where a run has none); a bool array of
    shape (n,). Only the failed runs' messages are read."""
    import numpy as np  # heavy: numpy

    if isinstance(status, (list, tuple)):
        status = np.asarray(status, dtype=object)
    rows = np.flatnonzero(np.asarray(status == "failed", dtype=bool))
    out = np.zeros(len(status), dtype=bool)
    out[rows] = [isinstance(m, str) and m.startswith(FALL_MESSAGES) for m in np.asarray(message, dtype=object)[rows]]
    return out


def computed(status: str, message: str | None) -> bool:
    """Whether a run was computed: it reached t_end (``"success"``) or :func:`fell`. A run
    that is not (a solver failure, a non-finite state, a step, wall-time or switching limit,
    an exception) has no result of its physics."""
    return status == "success" or fell(status, message)
