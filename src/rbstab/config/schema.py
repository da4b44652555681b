"""The configuration schema: value checks, pydantic models, and their error messages.

Each check takes the raw value and returns a plain-Python copy or raises
:class:`Invalid` with a short detail; what is *allowed* is the field's description.
:func:`problem_line` turns one pydantic error into our one-line message format.
"""

from __future__ import annotations

import difflib
import math
import numbers
import re
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from ..chain import MAX_BODIES, PARALLEL_AXES
from ..layout import BLOCK_UNITS, JOINT_KIND_OF, LIMITED, LIMITED_COMPONENTS, OUTPUTS, display_units, joint_kind, \
    point_fixed
from ..model import DISTURBANCE_KINDS, DISTURBANCE_QUANTITIES, MAX_DISTURBANCES, SATURATION_SHAPES, Limits
from ..variants import VARIANTS
from .physics import SINGULAR_RTOL

__all__ = [
    "DEFINITE_GAINS",
    "GAIN_UNITS",
    "GAIN_NAMES",
    "INITIAL_STATE_BLOCKS",
    "InitialStateSchema",
    "SimulationSettings",
    "SOLVER_METHODS",
    "MAX_MAGNITUDE",
    "MIN_INVERTED",
    "MAX_NAME_LENGTH",
    "MAX_SAMPLES",
    "BYTES_PER_SAMPLE",
    "MIN_SAMPLE_SPACING",
    "MAX_STEPS_LIMIT",
    "run_memory_estimate",
    "RunSchema",
    "TOP_LEVEL",
    "kind_of",
    "short_repr",
    "field_at",
    "problem_line",
    "submodel",
    "list_model",
    "field_check",
    "VECTOR_LENGTH",
    "within_bounds",
    "clear_of_gimbal_lock",
    "inside_limits",
    "limits_violation",
    "within_range",
    "samples_apart",
    "steps_suffice",
    "Invalid",
    "checked",
    "bounded_number",
    "optional",
    "run_name",
    "ChainSchema",
    "CHAIN_TOP_LEVEL",
    "BODY_GAINS",
    "JOINT_GAINS",
    "GROUND_NAME",
    "MAX_PART_NAME",
    "part_name",
]

#: Matrix gains of ``controller`` (:class:`rbstab.model.Gains`), with their units.
GAIN_UNITS = {
    "k_t": "N/m",
    "l_t": "N s/m",
    "k_r": "N m/rad",
    "l_r": "N m s/rad",
    "k_c": "N/m",
    "l_c": "N s/m",
    "k_d": "N/m",
    "l_d": "N s/m",
}
GAIN_NAMES = tuple(GAIN_UNITS)

#: ``initial_state`` config key -> state block name of :mod:`rbstab.layout`.
INITIAL_STATE_BLOCKS = {
    "theta": "theta",
    "omega": "omega",
    "x": "position",
    "v": "velocity",
    "d": "controller_state",
}

_NAME_PATTERN = re.compile(r"[A-Za-z0-9_.-]+")

# -- documented limits (docs/reliability.md): values no run can mean ---------------------------

#: Largest magnitude of any number of a configuration. The right-hand side multiplies up
#: to three such numbers and divides by a mass or an inertia (>= MIN_INVERTED), so with
#: these limits no term overflows a float (1e12^3 / 1e-12 = 1e48); 1e12 s is 31,700 years.
MAX_MAGNITUDE = 1e12
#: Smallest mass [kg] and smallest eigenvalue of the matrices the equations invert (the
#: inertia J [kg m^2], the damper L_d [N s/m]); below it their inverse overflows the dynamics.
MIN_INVERTED = 1e-12
#: Longest run ``name`` (it becomes ``<name>.h5`` and a hidden temporary ``.<name>.h5.*.tmp``,
#: within the 255 bytes most file systems allow).
MAX_NAME_LENGTH = 200
#: Memory a run holds per output sample [bytes] at its peak, when its file is written (the
#: state, 36 output columns, their post-processing and the file's image; measured ~1320 on
#: Case 3 with 10^6 samples).
BYTES_PER_SAMPLE = 1400
#: Most output samples of a run (~13 GiB of memory at :data:`BYTES_PER_SAMPLE`).
MAX_SAMPLES = 10_000_000
#: Closest sample spacing t_end / (n_samples - 1) [s]: closer samples are not distinct
#: times to the integrator and the numerical dv/dt divides by their spacing.
MIN_SAMPLE_SPACING = 1e-12
#: Largest ``simulation.max_steps``.
MAX_STEPS_LIMIT = 1_000_000_000


def run_memory_estimate(n_samples: int) -> int:
    """Memory [bytes] a run of ``n_samples`` output samples holds (:data:`BYTES_PER_SAMPLE` each)."""
    return int(n_samples) * BYTES_PER_SAMPLE


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.3g} GiB" if n_bytes >= 2**30 else f"{n_bytes / 2**20:.3g} MiB"
_SYMMETRY_RTOL = 1e-12
#: The ``method`` names of :func:`scipy.integrate.solve_ivp` (``scipy.integrate._ivp.ivp.METHODS``;
#: ``tests/test_config.py`` checks the two agree). Listed here so that validating a
#: configuration does not import scipy.integrate (~0.6 s, most of a sweep's planning).
SOLVER_METHODS = ("RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA")


class Invalid(Exception):
    def __init__(self, detail: str = "", expected: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.expected = expected


def kind_of(value: Any) -> str:
    """What a found value is, for messages: "null", "a boolean", "a string", "a number"..."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, numbers.Real):
        return "a number"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    return f"a {type(value).__name__}"


def _as_number(value: Any, *, allow_inf: bool = False) -> int | float:
    kind = type(value)
    if (kind is float or kind is int) and -MAX_MAGNITUDE <= value <= MAX_MAGNITUDE:  # without the ABC checks
        return value
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        detail = f"{kind_of(value)}, not a number"
        if isinstance(value, str):
            try:
                float(value)
                detail += "; remove the quotes"
            except ValueError:
                pass
        raise Invalid(detail)
    if isinstance(value, numbers.Integral):
        if abs(value) > MAX_MAGNITUDE:
            raise Invalid(_too_large(f"{float(value):.3g}" if abs(value) < 1e300 else f"an integer of {len(str(abs(value)))} digits"))
        return int(value)
    number = float(value)
    if math.isnan(number) or (math.isinf(number) and not allow_inf):
        raise Invalid("not a finite number")
    if math.isfinite(number) and abs(number) > MAX_MAGNITUDE:
        raise Invalid(_too_large(f"{number:.3g}"))
    return number


# -- the rules, on one value or on a column of values ----------------------------------------------
# The checks of this schema and the column checks of a sweep's runs (rbstab.sweep.validate)
# decide with these: each takes numbers, or numpy arrays element by element (NaN fails).


def within_bounds(value: Any, gt: float | None = None, ge: float | None = None, lt: float | None = None,
                  le: float | None = None) -> Any:
    """Whether ``value`` is within the bounds given (> gt, >= ge, < lt, <= le)."""
    ok = value == value  # noqa: PLR0124 - False for NaN
    if gt is not None:
        ok = ok & (value > gt)
    if ge is not None:
        ok = ok & (value >= ge)
    if lt is not None:
        ok = ok & (value < lt)
    if le is not None:
        ok = ok & (value <= le)
    return ok


def clear_of_gimbal_lock(theta_2: Any, margin: Any = 0.0) -> Any:
    """Whether |theta_2| < pi/2 - ``margin`` [rad]: B(theta) is singular at |theta_2| = pi/2
    (gimbal lock, eq 1)."""
    return abs(theta_2) < math.pi / 2 - margin


def inside_limits(values: Any, bounds: Any) -> Any:
    """Whether every |q_j,i| <= bound_j,i: ``values`` and ``bounds`` of shape (..., 5, 3), the
    rows those of :data:`rbstab.layout.LIMITED` (``simulation.limits``; inf: unbounded);
    shape (...). A NaN value is outside."""
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(np.asarray(values, dtype=float)) <= np.asarray(bounds, dtype=float), axis=(-2, -1))


def limits_violation(values: Any, bounds: Any) -> tuple[str, str] | None:
    """(the key ``simulation.limits.<quantity>``, a phrase ``|Omega_1| = 25 rad/s > 20
    rad/s``) of the first component of ``values`` (5, 3) beyond its bound in ``bounds`` (5,
    3) (:func:`inside_limits`), or None when all are inside."""
    values, bounds = np.asarray(values, dtype=float), np.asarray(bounds, dtype=float)
    with np.errstate(invalid="ignore"):
        outside = ~(np.abs(values) <= bounds)
    if not outside.any():
        return None
    j, i = (int(k) for k in np.argwhere(outside)[0])
    name = LIMITED[j]
    units = display_units(OUTPUTS[name].units)
    return (f"simulation.limits.{name}",
            f"|{LIMITED_COMPONENTS[name]}_{i + 1}| = {abs(values[j, i]):.6g} {units} > {bounds[j, i]:g} {units}")


def samples_apart(t_end: Any, n_samples: Any) -> Any:
    """Whether ``n_samples`` samples on [0, t_end] [s] are at least :data:`MIN_SAMPLE_SPACING` apart."""
    return t_end / (n_samples - 1) >= MIN_SAMPLE_SPACING


def starts_in_run(start: Any, t_end: Any) -> Any:
    """Whether a disturbance's ``start`` [s] is not after the run's ``t_end`` [s]."""
    return start <= t_end


def steps_suffice(t_end: Any, max_step: Any, max_steps: Any) -> Any:
    """Whether ``max_steps`` steps of at most ``max_step`` [s] can reach ``t_end`` [s]."""
    return t_end / max_step <= max_steps


def _too_large(found: str) -> str:
    return (f"{found}, beyond {MAX_MAGNITUDE:g} in magnitude, the largest a configuration takes: "
            "larger values overflow the dynamics (docs/reliability.md)")


def bounded_number(
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    allow_inf: bool = False,
    integer: bool = False,
    why: Callable[[Any], str] | None = None,
) -> Callable[[Any], int | float]:
    """A check of a number in bounds; ``why(value)`` explains a value out of them."""

    def check(value: Any) -> int | float:
        if integer and (isinstance(value, bool) or not isinstance(value, numbers.Integral)):
            raise Invalid(f"{kind_of(value)}, not an integer")
        number = _as_number(value, allow_inf=allow_inf)
        if not within_bounds(number, gt, ge, lt, le):
            raise Invalid(why(number) if why is not None else "")  # the description says what is allowed
        return number

    check.rule = ("number", {"gt": gt, "ge": ge, "lt": lt, "le": le, "allow_inf": allow_inf, "integer": integer})
    return check


def _entry(value: Any, where: str) -> int | float:
    try:
        return _as_number(value)
    except Invalid as exc:
        raise Invalid(f"entry {where} is {exc.detail}") from None


#: Entries of a vector of the configuration (a 3-vector; a 3x3 matrix has this many rows).
VECTOR_LENGTH = 3


def _vector(value: Any) -> list[int | float]:
    if type(value) is not list and not isinstance(value, (list, tuple)):
        raise Invalid(f"{kind_of(value)}, not a list")
    if len(value) != VECTOR_LENGTH:
        raise Invalid(f"{len(value)} entries, not {VECTOR_LENGTH}")
    return [_entry(x, f"[{i}]") for i, x in enumerate(value)]


def _symmetric_matrix(value: Any) -> tuple[list, np.ndarray | None]:
    """(the value as plain numbers, its eigenvalues or None for a diagonal given as 3 numbers)."""
    if not isinstance(value, (list, tuple)):
        raise Invalid(f"{kind_of(value)}, not a list")
    is_row = [isinstance(row, (list, tuple)) for row in value]
    if not any(is_row):
        return _vector(value), None
    if not all(is_row):
        raise Invalid("it mixes numbers and lists")
    lengths = sorted({len(row) for row in value})
    if len(value) != 3 or lengths != [3]:
        raise Invalid(f"a {len(value)}x{'/'.join(map(str, lengths))} list of lists")
    rows = [[_entry(x, f"[{i}][{j}]") for j, x in enumerate(row)] for i, row in enumerate(value)]
    matrix = np.array(rows, dtype=float)
    asymmetry = np.abs(matrix - matrix.T)
    if asymmetry.max() > _SYMMETRY_RTOL * np.abs(matrix).max():
        i, j = np.unravel_index(np.argmax(asymmetry), matrix.shape)
        raise Invalid(
            f"not symmetric: [{i}][{j}] = {matrix[i, j]:g} but [{j}][{i}] = {matrix[j, i]:g}"
        )
    return rows, np.linalg.eigvalsh(matrix)


def _spd_matrix(value: Any, why: str = "") -> list:
    """3 numbers (a positive diagonal) or a symmetric positive definite 3x3 list of lists.

    For the matrices the equations invert (the inertia J, the damper L_d of eq 22);
    ``why`` says so in the message of a singular one.
    """
    numbers, eigenvalues = _symmetric_matrix(value)
    reason = f"; {why}" if why else ""
    if eigenvalues is None:
        bad = [f"[{i}] = {x:g}" for i, x in enumerate(numbers) if not x > 0]
        if bad:
            raise Invalid(f"not positive definite: diagonal {', '.join(bad)}; each must be > 0{reason}")
        smallest = min(numbers)
    elif not eigenvalues[0] > 0:
        raise Invalid(f"not positive definite: smallest eigenvalue {eigenvalues[0]:g}{reason}")
    else:
        smallest = eigenvalues[0]
    if smallest < MIN_INVERTED:
        raise Invalid(f"smallest eigenvalue {smallest:g} is below {MIN_INVERTED:g}: the equations invert this "
                      "matrix, and its inverse would overflow the dynamics (docs/reliability.md)")
    return numbers


def _psd_matrix(value: Any) -> list:
    """3 numbers (a diagonal >= 0) or a symmetric positive semi-definite 3x3 list of lists.

    Zero eigenvalues are allowed (a gain of zero: no spring, no damper), down to
    -``SINGULAR_RTOL`` times the largest magnitude (the rounding of a singular matrix
    written with decimals); a negative one is not (a negative spring or damper feeds
    energy in, and v is no Lyapunov function).
    """
    numbers, eigenvalues = _symmetric_matrix(value)
    if eigenvalues is None:
        bad = [f"[{i}] = {x:g}" for i, x in enumerate(numbers) if not x >= 0]
        if bad:
            raise Invalid(
                f"not positive semi-definite: diagonal {', '.join(bad)}; each must be >= 0"
            )
    elif eigenvalues[0] < -SINGULAR_RTOL * np.abs(eigenvalues).max():
        raise Invalid(f"not positive semi-definite: smallest eigenvalue {eigenvalues[0]:g}")
    return numbers


def _theta(value: Any) -> list[int | float]:
    """Euler angles; the margin to gimbal lock is checked with the simulation section."""
    theta = _vector(value)
    if not clear_of_gimbal_lock(theta[1]):
        raise Invalid(
            "B(theta) is singular at |theta_2| = pi/2 (gimbal lock, eq 1)",
            "3 numbers (rad) with theta_2 in (-pi/2, pi/2)",
        )
    return theta


def optional(check: Callable[[Any], Any]) -> Callable[[Any], Any]:
    allowing_null = lambda value: None if value is None else check(value)  # noqa: E731
    allowing_null.rule = getattr(check, "rule", None)
    allowing_null.shape = getattr(check, "shape", ())
    return allowing_null


# The constraint each check stands for, in a form a batched check of many values reads
# (rbstab.sweep.table validates a sweep's columns with them): read by :func:`rbstab.config.paths.parse_key`.
_vector.rule = ("vector",)
_theta.rule = ("theta",)
_spd_matrix.rule = ("matrix", "definite")
_psd_matrix.rule = ("matrix", "semi-definite")
# The shape of the value each check takes (what a key path may index: ``.shape``; none: a
# single value), read by :func:`rbstab.config.paths.parse_key`.
_vector.shape = _theta.shape = (VECTOR_LENGTH,)
_spd_matrix.shape = _psd_matrix.shape = (VECTOR_LENGTH, VECTOR_LENGTH)


def _did_you_mean(word: str, choices: Sequence[str], prefix: str = "") -> str:
    match = difflib.get_close_matches(word, list(choices), n=1)
    return f"did you mean '{prefix}{match[0]}'?" if match else ""


def run_name(value: Any) -> str:
    if not isinstance(value, str):
        raise Invalid(f"{kind_of(value)}, not a string")
    if len(value) > MAX_NAME_LENGTH:
        raise Invalid(f"{len(value)} characters; at most {MAX_NAME_LENGTH}")
    if not _NAME_PATTERN.fullmatch(value) or set(value) == {"."}:
        raise Invalid()
    return value


def _variant(value: Any) -> str:
    if not isinstance(value, str):
        raise Invalid(f"{kind_of(value)}, not a string")
    if value not in VARIANTS:
        raise Invalid(_did_you_mean(value, list(VARIANTS)))
    return value


#: A tree joint's ``variant``: the paper's laws (:data:`rbstab.variants.VARIANTS`) and the
#: joint kinds that have no one-body form (:data:`rbstab.layout.JOINT_KIND_OF`).
JOINT_VARIANTS = (*VARIANTS, "hinge", "universal", "ball", "slide")
#: The joint kinds whose coordinates are along fixed axes (turns about them, a slide's
#: translation): their child's initial state is q, u; their gains, references and limits are
#: numbers per coordinate.
AXES_VARIANTS = tuple(v for v in JOINT_KIND_OF if joint_kind(v).axes)



def _pair(value: Any, check: Callable[[Any], Any]) -> list:
    """``check`` of each of 2 entries (a universal joint's, one per coordinate): :func:`_per_axis`'s."""
    return _per_axis(value, check, (2,))


def _is_pair(value: Any) -> bool:
    """Whether ``value`` is a list of 2 entries that are not lists (a universal joint's numbers)."""
    return isinstance(value, (list, tuple)) and len(value) == 2 and not any(isinstance(x, (list, tuple)) for x in value)


def _joint_variant(value: Any) -> str:
    if not isinstance(value, str):
        raise Invalid(f"{kind_of(value)}, not a string")
    if value not in JOINT_VARIANTS:
        raise Invalid(_did_you_mean(value, list(JOINT_VARIANTS)))
    return value


def _axis(value: Any) -> list:
    """A hinge's axis: 3 numbers, not all zero (it is normalised); a universal joint's two
    axes: 2 such lists, not parallel."""
    if isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(a, (list, tuple)) for a in value):
        axes = _pair(value, _axis)
        if np.linalg.norm(np.cross(*(np.asarray(a, dtype=float) / np.linalg.norm(a) for a in axes))) < PARALLEL_AXES:
            raise Invalid("two parallel axes", "2 lists of 3 numbers, the axes a_1 and a_2 not parallel")
        return axes
    axis = _vector(value)
    if not math.hypot(*axis) > 0.0:
        raise Invalid("an axis of zero length", "3 numbers, not all zero (the axis, normalised)")
    return axis


def _joint_gain(value: Any) -> Any:
    """A joint's spring or damper: a number >= 0 (a hinge's, about its axis), 2 of them (a
    universal joint's, one per coordinate) or a positive semi-definite 3x3
    (:func:`_psd_matrix`; the kind decides which it must be)."""
    if _is_pair(value):
        return _pair(value, bounded_number(ge=0))
    if isinstance(value, (list, tuple)):
        return _psd_matrix(value)
    return bounded_number(ge=0)(value)


def _joint_angles(value: Any) -> Any:
    """A reference posture: a number (a hinge's q_ref, rad), 2 (a universal joint's) or 3
    Euler angles (:func:`_theta`)."""
    if _is_pair(value):
        return _pair(value, _as_number)
    if isinstance(value, (list, tuple)):  # Euler angles (their gimbal lock: the chain's check) or a rotation vector
        return _vector(value)
    return _as_number(value)


_joint_gain.rule, _joint_gain.shape = ("matrix", "semi-definite"), (3, 3)
_joint_angles.rule, _joint_angles.shape = ("theta",), (3,)


def _method(value: Any) -> str:
    methods = SOLVER_METHODS
    expected = f"one of {', '.join(methods)} (scipy solve_ivp methods)"
    if not isinstance(value, str):
        raise Invalid(f"{kind_of(value)}, not a string", expected)
    if value not in methods:
        by_case = {m.lower(): m for m in methods}
        hint = f"did you mean '{by_case[value.lower()]}'?" if value.lower() in by_case else ""
        raise Invalid(hint or _did_you_mean(value, methods), expected)
    return value


def _max_step(value: Any) -> float:
    """null means inf (that is how :attr:`RunConfig.resolved` writes inf)."""
    return math.inf if value is None else bounded_number(gt=0, allow_inf=True)(value)


def _max_wall_time(value: Any) -> float:
    """null means inf (no wall-time limit; the step limit still ends the run)."""
    return math.inf if value is None else bounded_number(gt=0, allow_inf=True)(value)


_max_step.rule = _max_wall_time.rule = ("number", {"gt": 0, "ge": None, "lt": None, "le": None, "allow_inf": True,
                                                   "integer": False})


def _samples_memory(n: Any) -> str:
    return (f"a run holds ~{BYTES_PER_SAMPLE} bytes per sample: {n} samples would need "
            f"~{_gib(run_memory_estimate(n))}, at most {MAX_SAMPLES} (~{_gib(run_memory_estimate(MAX_SAMPLES))}) are allowed")


def checked(check: Callable[[Any], Any]) -> BeforeValidator:
    def validate(value: Any) -> Any:
        try:
            return check(value)
        except Invalid as exc:
            ctx = {"detail": exc.detail}
            if exc.expected:
                ctx["expected"] = exc.expected
            raise PydanticCustomError("rbstab_invalid", "invalid value {detail}", ctx) from None

    validate.rule = getattr(check, "rule", None)
    validate.shape = getattr(check, "shape", ())
    return BeforeValidator(validate)


@dataclass(frozen=True)
class SimulationSettings:
    """Integration settings of one run (``simulation`` section).

    Attributes
    ----------
    t_end : float
        Final time [s], > 0; the run starts at t = 0.
    n_samples : int
        Number of output samples on [0, t_end], >= 2.
    method : str
        scipy ``solve_ivp`` method.
    rtol, atol : float
        Relative and absolute tolerances of the solver, > 0.
    max_step : float
        Largest solver step [s], > 0; ``inf`` for no limit.
    gimbal_margin : float
        [rad] in (0, 0.5): the run stops when |theta_2| >= pi/2 - gimbal_margin.
    max_steps : int
        Accepted solver steps after which the run stops as ``failed`` (every engine).
    max_wall_time : float
        Wall time [s] of the integration after which the run stops as ``failed`` (every
        engine); ``inf`` for none (the step limit still ends it).
    limits : Limits or None
        The admissible region (``simulation.limits``); a run that leaves it stops as
        ``failed``, its message naming the bound and the time. None: unbounded.
    """

    t_end: float = 2.0
    n_samples: int = 2001
    method: str = "DOP853"
    rtol: float = 1e-8
    atol: float = 1e-10
    max_step: float = math.inf
    gimbal_margin: float = 1e-3
    max_steps: int = 1_000_000
    max_wall_time: float = 600.0
    limits: Limits | None = None


# -- schema --------------------------------------------------------------------------------

_VECTOR = Annotated[Any, checked(_vector)]


def _zero() -> list[float]:
    """The default of a 3-vector: a new list each time (defaults are not validated, and a
    resolved configuration is plain lists)."""
    return [0.0, 0.0, 0.0]

#: Gains the equations invert, with the reason: these must be positive definite. Every
#: other gain may be positive semi-definite (zero included: no spring or damper there).
DEFINITE_GAINS = {
    "l_d": "L_d is inverted in dD/dt = L_d^-1 (K_c (E - D) - K_d D) (eq 22)",
}


def _gain_type(name: str) -> Any:
    if name in DEFINITE_GAINS:
        check = lambda value: _spd_matrix(value, DEFINITE_GAINS[name])  # noqa: E731
        check.rule, check.shape = _spd_matrix.rule, _spd_matrix.shape
    else:
        check = _psd_matrix
    return Annotated[Any, checked(optional(check))]


_JOINT_GAIN = Annotated[Any, checked(optional(_joint_gain))]


def _gain(name: str) -> Any:
    kind = "definite" if name in DEFINITE_GAINS else "semi-definite"
    return Field(
        None,
        validate_default=True,
        description="3 numbers (a diagonal) or a 3x3 list of lists, "
        f"symmetric positive {kind} ({GAIN_UNITS[name]})",
    )


def _mapping_of(model: type[BaseModel]) -> str:
    return f"a mapping with keys {', '.join(model.model_fields)}"


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class _Body(_Section):
    mass: Annotated[Any, checked(bounded_number(gt=0))] = Field(description="a number > 0 (kg)")
    inertia: Annotated[Any, checked(_spd_matrix)] = Field(
        description="3 numbers (principal moments) or a 3x3 list of lists, "
        "symmetric positive definite (kg m^2)"
    )
    attachment_point: _VECTOR = Field(description="3 numbers (R, body frame, m)")
    gravity: _VECTOR = Field(default_factory=_zero, description="3 numbers (g, inertial frame, m/s^2)")


def _per_axis(value: Any, check: Callable[[Any], Any], lengths: tuple[int, ...] = (3,)) -> Any:
    """``check`` of one number (every axis), or of each of 3 (a list: one per axis; with 2
    in ``lengths``, 2: a universal joint's, one per coordinate)."""
    if isinstance(value, (list, tuple)):
        if len(value) not in lengths:
            raise Invalid(f"{len(value)} entries, not {' or '.join(map(str, lengths[::-1]))}")
        out = []
        for i, x in enumerate(value):
            try:
                out.append(check(x))
            except Invalid as exc:
                raise Invalid(f"entry [{i}] is {exc.detail or _out_of_bounds(x, check)}") from None
        return out
    return check(value)


def _out_of_bounds(value: Any, check: Callable[[Any], Any]) -> str:
    """``0, not > 0``: a number that ``check`` (a :func:`bounded_number`) refused for its bounds."""
    bounds = getattr(check, "rule", (None, {}))[1]
    words = [f"{op} {bounds[name]:g}" for name, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
             if bounds.get(name) is not None]
    return f"{value!r}, not {' and '.join(words)}" if words else repr(value)


def _limits(value: Any) -> float | list[float]:
    """An actuator's limit on every axis (a number > 0; .inf: none) or one per axis (3)."""
    return _per_axis(value, bounded_number(gt=0, allow_inf=True))


_limits.rule = ("limits", {"gt": 0, "ge": None, "lt": None, "le": None, "allow_inf": True, "integer": False})
_limits.shape = (VECTOR_LENGTH,)
_LIMITS = Annotated[Any, checked(optional(_limits))]


def _lower_limits(value: Any) -> float | list[float]:
    """An actuator's lower limit on every axis (a number < 0; -.inf: none) or one per axis (3)."""
    return _per_axis(value, bounded_number(lt=0, allow_inf=True))


_lower_limits.rule = ("limits", {"gt": None, "ge": None, "lt": 0, "le": None, "allow_inf": True, "integer": False})
_lower_limits.shape = (VECTOR_LENGTH,)


def _joint_limits(value: Any) -> float | list[float]:
    """A joint's actuator limits: :func:`_limits`, or 2 (a universal joint's, per coordinate)."""
    return _per_axis(value, bounded_number(gt=0, allow_inf=True), (2, 3))


def _joint_lower_limits(value: Any) -> float | list[float]:
    """A joint's lower actuator limits: :func:`_lower_limits`, or 2 (a universal joint's)."""
    return _per_axis(value, bounded_number(lt=0, allow_inf=True), (2, 3))


_joint_limits.rule, _joint_limits.shape = _limits.rule, _limits.shape
_joint_lower_limits.rule, _joint_lower_limits.shape = _lower_limits.rule, _lower_limits.shape


def _shape(value: Any) -> str:
    if not isinstance(value, str):
        raise Invalid(f"{kind_of(value)}, not a string")
    if value not in SATURATION_SHAPES:
        raise Invalid(_did_you_mean(value, list(SATURATION_SHAPES)))
    return value


class _Saturation(_Section):
    """What the actuators can deliver (:class:`rbstab.model.Saturation`)."""

    torque_n: _LIMITS = Field(None, description="|N_i| <= limit (N m, body frame): a number > 0 or 3 of them "
                                                "(.inf: none)")
    force_h: _LIMITS = Field(None, description="|H_i| <= limit (N, inertial frame): a number > 0 or 3 of them")
    constraint_force: _LIMITS = Field(None, description="|Lambda_i| <= limit (N, inertial frame): a number > 0 "
                                                        "or 3 of them (not permanent)")
    shape: Annotated[Any, checked(_shape)] = Field("clip", description=f"one of {', '.join(SATURATION_SHAPES)}")


class _Controller(_Section):
    # ``variant`` first: the gain validators read it from ``info.data``.
    variant: Annotated[Any, checked(_variant)] = Field(description=f"one of {', '.join(VARIANTS)}")
    k_t: _gain_type("k_t") = _gain("k_t")
    l_t: _gain_type("l_t") = _gain("l_t")
    k_r: _gain_type("k_r") = _gain("k_r")
    l_r: _gain_type("l_r") = _gain("l_r")
    k_c: _gain_type("k_c") = _gain("k_c")
    l_c: _gain_type("l_c") = _gain("l_c")
    k_d: _gain_type("k_d") = _gain("k_d")
    l_d: _gain_type("l_d") = _gain("l_d")
    k_s: Annotated[Any, checked(optional(bounded_number(ge=0)))] = Field(
        None, validate_default=True, description="a number >= 0 (N)"
    )
    boundary_layer: Annotated[Any, checked(bounded_number(ge=0))] = Field(
        0.0, description="a number >= 0 (m; 0 = pure sign function)"
    )
    saturation: _Saturation | None = Field(None, description=_mapping_of(_Saturation) + " (optional)")

    @model_validator(mode="after")
    def _saturation_fits_the_variant(self) -> "_Controller":
        """A limit of Lambda where Lambda is no actuator's: the pin's reaction (permanent),
        or the pure sign law's switching force (its magnitude is K_s already)."""
        limit = None if self.saturation is None else self.saturation.constraint_force
        if limit is None:
            return self
        if point_fixed(self.variant):
            raise PydanticCustomError("rbstab_invalid", "limit on the pin", {
                "key": "controller.saturation.constraint_force", "found": short_repr(limit),
                "expected": "no limit with variant 'permanent'",
                "detail": "Lambda is the pin's reaction, not an actuator's force"})
        if self.variant == "sliding" and float(self.boundary_layer) == 0.0:
            raise PydanticCustomError("rbstab_invalid", "limit on the sign law", {
                "key": "controller.saturation.constraint_force", "found": short_repr(limit),
                "expected": "no limit with the pure sign law (boundary_layer: 0)",
                "detail": "its force is K_s sgn(E): set controller.k_s to at most the limit instead"})
        return self

    @field_validator(*GAIN_NAMES, "k_s", mode="after")
    @classmethod
    def _required_by_variant(cls, value: Any, info: ValidationInfo) -> Any:
        variant = info.data.get("variant")  # absent if the variant itself is invalid
        required = variant is not None and info.field_name in VARIANTS[variant].required_gains
        if value is None and required:
            raise PydanticCustomError(
                "rbstab_missing", "missing", {"detail": f"required by variant '{variant}'"}
            )
        return value


def _choice(options: Sequence[str]) -> Callable[[Any], str]:
    def check(value: Any) -> str:
        if not isinstance(value, str):
            raise Invalid(f"{kind_of(value)}, not a string")
        if value not in options:
            raise Invalid(_did_you_mean(value, list(options)))
        return value

    return check


def _band(value: Any) -> list[float]:
    """[f_lo, f_hi] [Hz] with 0 <= f_lo < f_hi < inf."""
    if not isinstance(value, (list, tuple)):
        raise Invalid(f"{kind_of(value)}, not a list")
    if len(value) != 2:
        raise Invalid(f"{len(value)} entries, not 2")
    lo, hi = (bounded_number(ge=0)(x) for x in value)
    if hi <= lo:
        raise Invalid(f"f_hi = {hi:g} <= f_lo = {lo:g}")
    return [lo, hi]


def _rms(value: Any) -> list[float]:
    """An RMS on every axis (a number >= 0) or one per axis (3), not all zero."""
    out = _per_axis(value, bounded_number(ge=0))
    if not isinstance(out, list):
        out = [out] * 3
    if not any(out):
        raise Invalid("every axis 0")
    return out


_band.rule = None
_band.shape = (2,)
_rms.rule = ("limits", {"gt": None, "ge": 0, "lt": None, "le": None, "allow_inf": False, "integer": False})
_rms.shape = (VECTOR_LENGTH,)

#: The keys of a disturbance each kind takes (besides kind, quantity, start), and those it needs.
DISTURBANCE_KEYS = {
    "impulse": ("value", "point"),
    "pulse": ("value", "point", "duration"),
    "step": ("value", "point"),
    "sine": ("value", "point", "frequency", "phase"),
    "noise": ("point", "band", "rms", "seed"),
}
_NEEDED = {"impulse": ("value",), "pulse": ("value", "duration"), "step": ("value",), "sine": ("value", "frequency"),
           "noise": ("band", "rms", "seed")}


class _Disturbance(_Section):
    """One disturbance (:class:`rbstab.model.Disturbance`, docs/disturbances.md)."""

    kind: Annotated[Any, checked(_choice(tuple(DISTURBANCE_KINDS)))] = Field(
        description=f"one of {', '.join(DISTURBANCE_KINDS)}")
    quantity: Annotated[Any, checked(_choice(tuple(DISTURBANCE_QUANTITIES)))] = Field(
        "force", description="force (at point, inertial frame) or torque (body frame)")
    value: Annotated[Any, checked(optional(_vector))] = Field(
        None, description="3 numbers: impulse (N s or N m s); pulse, step, sine amplitude (N or N m)")
    point: Annotated[Any, checked(optional(_vector))] = Field(
        None, description="3 numbers (m, body frame, from the centre of mass; force only)")
    start: Annotated[Any, checked(bounded_number(ge=0))] = Field(
        0.0, description="a number in [0, simulation.t_end] (s)")
    duration: Annotated[Any, checked(optional(bounded_number(gt=0)))] = Field(
        None, description="a number > 0 (s; pulse only)")
    frequency: Annotated[Any, checked(optional(bounded_number(gt=0)))] = Field(
        None, description="a number > 0 (Hz; sine only)")
    phase: Annotated[Any, checked(optional(bounded_number()))] = Field(
        None, description="a number (rad; sine only)")
    band: Annotated[Any, checked(optional(_band))] = Field(
        None, description="[f_lo, f_hi] (Hz; noise only) with 0 <= f_lo < f_hi")
    rms: Annotated[Any, checked(optional(_rms))] = Field(
        None, description="a number >= 0 or 3 of them (N or N m; noise only)")
    seed: Annotated[Any, checked(optional(bounded_number(ge=0, le=2**31 - 1, integer=True)))] = Field(
        None, description="an integer in [0, 2^31 - 1] (noise only)")

    @model_validator(mode="after")
    def _keys_fit_the_kind(self) -> "_Disturbance":
        takes = DISTURBANCE_KEYS[self.kind]
        for key in ("value", "point", "duration", "frequency", "phase", "band", "rms", "seed"):
            value = getattr(self, key)
            if value is not None and key not in takes:
                raise PydanticCustomError("rbstab_invalid", "key of another kind", {
                    "subkey": key, "found": short_repr(value), "expected": f"no {key} with kind '{self.kind}' "
                    f"(it takes {', '.join(takes)})"})
            if value is None and key in _NEEDED[self.kind]:
                raise PydanticCustomError("rbstab_invalid", "missing", {
                    "subkey": key, "found": "nothing", "expected": f"{key} with kind '{self.kind}': "
                    + (type(self).model_fields[key].description or "")})
        if self.quantity == "torque" and self.point is not None:
            raise PydanticCustomError("rbstab_invalid", "point on a torque", {
                "subkey": "point", "found": short_repr(self.point),
                "expected": "no point with quantity 'torque' (a torque has no point of application)"})
        return self


class InitialStateSchema(_Section):
    """One body's initial state: a one-body config's ``initial_state``, or an entry of a
    chain config's (by body name)."""

    theta: Annotated[Any, checked(_theta)] = Field(
        default_factory=_zero, description=f"3 numbers ({BLOCK_UNITS['theta']})"
    )
    omega: _VECTOR = Field(default_factory=_zero, description=f"3 numbers ({BLOCK_UNITS['omega']}, body frame)")
    x: _VECTOR = Field(default_factory=_zero, description=f"3 numbers ({BLOCK_UNITS['position']})")
    v: _VECTOR = Field(default_factory=_zero, description=f"3 numbers ({BLOCK_UNITS['velocity']})")
    d: _VECTOR = Field(default_factory=_zero, description=f"3 numbers ({BLOCK_UNITS['controller_state']})")


def _joint_coordinate(value: Any) -> Any:
    """A joint's coordinate: a hinge's or a slide's number, or a universal joint's 2 (a turn's
    in (-pi, pi) [rad]: the chain's check, which knows the kind)."""
    return _pair(value, _as_number) if _is_pair(value) else _as_number(value)


def _joint_rate(value: Any) -> Any:
    """A joint's angular rate [rad/s]: a hinge's number, or a universal joint's 2."""
    return _pair(value, _as_number) if _is_pair(value) else _as_number(value)


_joint_coordinate.shape = (2,)
_joint_rate.shape = (2,)


class _ChainInitialState(InitialStateSchema):
    """One body's initial state in a chain: its blocks, or a hinge's child's joint angle and rate."""

    q: Annotated[Any, checked(optional(_joint_coordinate))] = Field(
        None, description="a number in (-pi, pi) (rad): the angle q of the hinge that holds the body (only for a "
                          "hinge's child; default 0); a universal joint's child's: 2, q_1 and q_2; a slide's child's: "
                          "a number (m), its displacement along the axis")
    u: Annotated[Any, checked(optional(_joint_rate))] = Field(
        None, description="a number (rad/s): dq/dt of the hinge that holds the body (only for a hinge's child; "
                          "default 0); a universal joint's child's: 2; a slide's child's: a number (m/s)")


#: A hinge's child's initial-state keys, and the blocks its hinge places instead.
HINGE_STATE = ("q", "u")


class _Limits(_Section):
    """The admissible region (:class:`rbstab.model.Limits`): |q_i| <= bound."""

    theta: _LIMITS = Field(None, description="|theta_i| <= bound (rad): a number > 0 or 3 of them (.inf: none)")
    omega: _LIMITS = Field(None, description="|Omega_i| <= bound (rad/s, body frame): a number > 0 or 3 of them")
    position: _LIMITS = Field(None, description="|X_i| <= bound (m, centre of mass, inertial frame): a number > 0 "
                                                "or 3 of them")
    velocity: _LIMITS = Field(None, description="|V_i| <= bound (m/s, inertial frame): a number > 0 or 3 of them")
    constraint_error: _LIMITS = Field(None, description="|E_i| <= bound (m, inertial frame): a number > 0 or 3 of "
                                                        "them (not permanent)")


_DEFAULT_SIMULATION = SimulationSettings()


class _Simulation(_Section):
    t_end: Annotated[Any, checked(bounded_number(gt=0))] = Field(
        _DEFAULT_SIMULATION.t_end, description="a number > 0 (s)"
    )
    n_samples: Annotated[Any, checked(bounded_number(ge=2, le=MAX_SAMPLES, integer=True, why=_samples_memory))] = Field(
        _DEFAULT_SIMULATION.n_samples, description=f"an integer in [2, {MAX_SAMPLES}]"
    )
    method: Annotated[Any, checked(_method)] = Field(
        _DEFAULT_SIMULATION.method, description="a scipy solve_ivp method name"
    )
    rtol: Annotated[Any, checked(bounded_number(gt=0))] = Field(
        _DEFAULT_SIMULATION.rtol, description="a number > 0"
    )
    atol: Annotated[Any, checked(bounded_number(gt=0))] = Field(
        _DEFAULT_SIMULATION.atol, description="a number > 0"
    )
    max_step: Annotated[Any, checked(_max_step)] = Field(
        _DEFAULT_SIMULATION.max_step, description="a number > 0 (s), .inf or null for no limit"
    )
    gimbal_margin: Annotated[Any, checked(bounded_number(gt=0, lt=0.5))] = Field(
        _DEFAULT_SIMULATION.gimbal_margin, description="a number in (0, 0.5) (rad)"
    )
    max_steps: Annotated[Any, checked(bounded_number(ge=1, le=MAX_STEPS_LIMIT, integer=True))] = Field(
        _DEFAULT_SIMULATION.max_steps, description=f"an integer in [1, {MAX_STEPS_LIMIT}] (solver steps)"
    )
    max_wall_time: Annotated[Any, checked(_max_wall_time)] = Field(
        _DEFAULT_SIMULATION.max_wall_time, description="a number > 0 (s), .inf or null for no limit"
    )
    limits: _Limits | None = Field(None, description=_mapping_of(_Limits) + " (optional: the admissible region)")

    @model_validator(mode="after")
    def _run_can_end(self) -> "_Simulation":
        """Settings no run can meet: samples closer than MIN_SAMPLE_SPACING, or a max_step
        that needs more steps than max_steps to reach t_end."""
        spacing = self.t_end / (self.n_samples - 1)
        if not samples_apart(self.t_end, self.n_samples):
            raise PydanticCustomError("rbstab_invalid", "samples too close", {
                "key": "simulation.t_end",
                "found": short_repr(self.t_end),
                "expected": f"t_end >= (n_samples - 1) * {MIN_SAMPLE_SPACING:g} s = "
                            f"{(self.n_samples - 1) * MIN_SAMPLE_SPACING:.6g} s",
                "detail": f"{self.n_samples} samples would be {spacing:.3g} s apart, closer than "
                          f"{MIN_SAMPLE_SPACING:g} s; shorten n_samples or lengthen t_end",
            })
        needed = self.t_end / self.max_step
        if not steps_suffice(self.t_end, self.max_step, self.max_steps):
            raise PydanticCustomError("rbstab_invalid", "max_step too small", {
                "key": "simulation.max_step",
                "found": short_repr(self.max_step),
                "expected": f"max_step >= t_end / max_steps = {self.t_end / self.max_steps:.6g} s",
                "detail": f"reaching t_end = {self.t_end:g} s takes at least {needed:.3g} steps of max_step, "
                          f"more than simulation.max_steps = {self.max_steps}",
            })
        return self


class _Run(_Section):
    """What both spellings of a run share: its sections' validators (the fields are each
    spelling's own)."""

    @field_validator("disturbances", mode="before", check_fields=False)
    @classmethod
    def _few_disturbances(cls, value: Any) -> Any:
        if isinstance(value, (list, tuple)) and len(value) > MAX_DISTURBANCES:
            raise PydanticCustomError("rbstab_invalid", "too many disturbances", {
                "key": "disturbances", "found": f"{len(value)} entries",
                "expected": f"at most {MAX_DISTURBANCES} disturbances"})
        return value

    @field_validator("initial_state", "simulation", mode="before", check_fields=False)
    @classmethod
    def _empty_section(cls, value: Any) -> Any:
        return {} if value is None else value  # "simulation:" with every line commented out


class RunSchema(_Run):
    """The whole run configuration (pydantic model; the public result is ``RunConfig``)."""

    name: Annotated[Any, checked(run_name)] = Field(
        description="a name of letters, digits, '_', '.' and '-' (it becomes a file name)"
    )
    body: _Body = Field(description=_mapping_of(_Body))
    controller: _Controller = Field(description=_mapping_of(_Controller))
    initial_state: InitialStateSchema = Field(
        default_factory=InitialStateSchema, description=_mapping_of(InitialStateSchema)
    )
    # validate_default: the theta check below must also run when the section is absent.
    simulation: _Simulation = Field(
        default_factory=_Simulation, validate_default=True, description=_mapping_of(_Simulation)
    )
    disturbances: list[_Disturbance] | None = Field(
        None, json_schema_extra={"max_entries": MAX_DISTURBANCES}, description=f"a list of at most {MAX_DISTURBANCES} disturbances, each {_mapping_of(_Disturbance)} "
                          "(optional; docs/disturbances.md)")

    @model_validator(mode="after")
    def _disturbances_fit_the_run(self) -> "RunSchema":
        """A start after t_end; disturbances on the pure sign law (its event-driven
        integrator has no breakpoints)."""
        for i, d in enumerate(self.disturbances or ()):
            if not starts_in_run(float(d.start), float(self.simulation.t_end)):
                raise PydanticCustomError("rbstab_invalid", "start after the end", {
                    "key": f"disturbances.{i}.start", "found": short_repr(d.start),
                    "expected": f"a number in [0, simulation.t_end] = [0, {float(self.simulation.t_end):g}] (s)"})
            if self.controller.variant == "sliding" and float(self.controller.boundary_layer) == 0.0:
                raise PydanticCustomError("rbstab_invalid", "disturbance on the sign law", {
                    "key": f"disturbances.{i}", "found": f"kind '{d.kind}'",
                    "expected": "no disturbances with the pure sign law (controller.boundary_layer: 0)",
                    "detail": "its event-driven integrator takes no disturbances; give the sign law a boundary "
                              "layer > 0 instead"})
        return self

    @model_validator(mode="after")
    def _limits_fit_the_variant(self) -> "RunSchema":
        """A bound of E on ``permanent``, whose C is pinned (E = 0 at every instant)."""
        limits = self.simulation.limits
        if limits is not None and limits.constraint_error is not None and point_fixed(self.controller.variant):
            raise PydanticCustomError("rbstab_invalid", "bound of E on the pin", {
                "key": "simulation.limits.constraint_error", "found": short_repr(limits.constraint_error),
                "expected": "no bound with variant 'permanent'",
                "detail": "C is pinned: E = 0 at every instant; bound theta, omega, position or velocity"})
        return self

    @field_validator("simulation", mode="after")
    @classmethod
    def _theta_clear_of_gimbal_lock(cls, value: _Simulation, info: ValidationInfo) -> _Simulation:
        state = info.data.get("initial_state")
        if state is None:
            return value
        limit = math.pi / 2 - value.gimbal_margin
        if not clear_of_gimbal_lock(state.theta[1], value.gimbal_margin):
            raise PydanticCustomError(
                "rbstab_invalid",
                "theta_2 too close to gimbal lock",
                {
                    "key": "initial_state.theta",
                    "found": short_repr(state.theta),
                    "expected": "3 numbers (rad) with theta_2 in (-pi/2 + gimbal_margin, "
                    f"pi/2 - gimbal_margin) = ({-limit:.6g}, {limit:.6g})",
                    "detail": "B(theta) is singular at |theta_2| = pi/2 (gimbal lock, eq 1); "
                    f"gimbal_margin = {value.gimbal_margin:g}",
                },
            )
        return value


# -- chains of bodies ------------------------------------------------------------------------------
# A chain configuration (``bodies`` and ``joints`` instead of ``body`` and ``controller``):
# validated here like a one-body one; rbstab.config.loader builds its rbstab.chain.Chain.

#: Gains of a chain's body: the ground-anchored feedback H (eq 24), zero when absent.
BODY_GAINS = ("k_t", "l_t")
#: Gains of a chain's joint: its rotational feedback (eq 23, zero when absent: a passive
#: joint) and those of its point law that its variant needs (``required_gains``).
JOINT_GAINS = ("k_r", "l_r", "k_c", "l_c", "k_d", "l_d")
#: The name of a joint's parent that is the inertial frame.
GROUND_NAME = "ground"
#: Longest name of a body or joint.
MAX_PART_NAME = 64
_PART_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")
_PART_NAME_RULE = ("a name of letters, digits, '_' and '-' that starts with a letter or '_' (it is part of "
                   f"dotted keys), at most {MAX_PART_NAME} characters")


def part_name(value: Any) -> str:
    """The name of a body or a joint: it appears in dotted keys, files and reports."""
    if not isinstance(value, str):
        raise Invalid(f"{kind_of(value)}, not a string")
    if len(value) > MAX_PART_NAME:
        raise Invalid(f"{len(value)} characters; at most {MAX_PART_NAME}")
    if not _PART_NAME.fullmatch(value):
        raise Invalid()
    return value


_PART = Annotated[Any, checked(part_name)]


class _BodySaturation(_Section):
    """What a body's ground-anchored actuator can deliver (H, eq 24)."""

    force_h: _LIMITS = Field(None, description="|H_i| <= limit (N, inertial frame): a number > 0 or 3 of them "
                                               "(.inf: none)")
    shape: Annotated[Any, checked(_shape)] = Field("clip", description=f"one of {', '.join(SATURATION_SHAPES)}")


class _JointSaturation(_Section):
    """What a joint's actuators can deliver: its torque N_j and its point force Lambda_j."""

    torque_n: Annotated[Any, checked(optional(_joint_limits))] = Field(
        None, description="|N_i| <= limit (N m, child frame): a number > 0 or 3 of them (a universal joint's: 2, one "
                          "per coordinate; a slide's: a number, its force along its axis, N) (.inf: none; with "
                          "torque_n_lower, the upper limits)")
    torque_n_lower: Annotated[Any, checked(optional(_joint_lower_limits))] = Field(
        None, description="N_i >= lower limit (N m, child frame): a number < 0 or 3 of them (-.inf: none; optional, "
                          "default -torque_n: an actuator stronger one way, as MJCF's forcerange)")
    constraint_force: _LIMITS = Field(None, description="|Lambda_i| <= limit (N, inertial frame): a number > 0 "
                                                        "or 3 of them (not permanent)")
    shape: Annotated[Any, checked(_shape)] = Field("clip", description=f"one of {', '.join(SATURATION_SHAPES)}")


class _JointPassive(_Section):
    """A joint's passive visco-elastic torque (ligaments, cartilage): never limited."""

    k_r: _JOINT_GAIN = Field(None, validate_default=True, description=(
        "3 numbers (a diagonal) or a 3x3 list of lists, symmetric positive semi-definite; a hinge's: a number >= 0 "
        "(N m/rad; default 0)"))
    l_r: _JOINT_GAIN = Field(None, validate_default=True, description=(
        "3 numbers (a diagonal) or a 3x3 list of lists, symmetric positive semi-definite; a hinge's: a number >= 0 "
        "(N m s/rad; default 0)"))
    theta_ref: Annotated[Any, checked(optional(_joint_angles))] = Field(
        None, description="3 numbers (rad; the relative Euler angles at which its spring is relaxed); a hinge's: a "
                          "number (rad; default 0)")


#: What a joint's range means: a stop (a one-sided spring and damper beyond either end) or an
#: admissible region (a run whose coordinate leaves it stops there, fell).
RANGE_KINDS = ("stop", "region")


def _per_coordinate(**bounds) -> Callable[[Any], Any]:
    """A check of a range's number: one (a hinge's; a ball's for each Euler angle) or 3 (a
    ball's, one per Euler angle of Theta_j) within ``bounds`` (:func:`bounded_number`'s)."""
    def check(value: Any) -> Any:
        return _per_axis(value, bounded_number(**bounds), (2, 3))

    check.rule = ("limits", {"gt": None, "ge": None, "lt": None, "le": None, "allow_inf": False, "integer": False,
                             **bounds})
    check.shape = (VECTOR_LENGTH,)
    return check


def within_range(bounds: tuple[np.ndarray, np.ndarray]) -> str:
    """What a range (lower, upper) allows, as a message writes it: ``an angle in the range [0,
    0.2] (rad)`` (a hinge's), or each Euler angle in its own (a ball's)."""
    lower, upper = np.broadcast_arrays(*bounds)
    if lower.ndim == 0:
        return f"an angle in the range [{float(lower):g}, {float(upper):g}] (rad)"
    if lower.shape == (2,):
        return "angles in the range " + ", ".join(f"q_{i + 1} in [{float(a):g}, {float(b):g}]"
                                                  for i, (a, b) in enumerate(zip(lower, upper))) + " (rad)"
    return "Euler angles in the range " + ", ".join(f"theta_{i + 1} in [{float(a):g}, {float(b):g}]"
                                                     for i, (a, b) in enumerate(zip(lower, upper))) + " (rad)"


class _JointRange(_Section):
    """A hinge's or a ball's range of motion: a stop (beyond either end a one-sided spring
    and damper) or an admissible region (a run that leaves it fell)."""

    lower: Annotated[Any, checked(_per_coordinate(allow_inf=True))] = Field(
        description="a number (rad; the range's lower end, -.inf: none); a ball's: 3, one per Euler angle of Theta_j; "
                    "a slide's: m")
    upper: Annotated[Any, checked(_per_coordinate(allow_inf=True))] = Field(
        description="a number > lower (rad; the range's upper end, .inf: none); a ball's: 3")
    kind: Annotated[Any, checked(_choice(RANGE_KINDS))] = Field(
        "stop", description="stop (default: beyond either end a one-sided spring k_r and damper l_r) or region (an "
                            "admissible region: a run whose angle leaves it stops there and fell; no k_r, l_r)")
    k_r: Annotated[Any, checked(optional(_per_coordinate(gt=0)))] = Field(
        None, description="a number > 0 (N m/rad; the stop's stiffness beyond an end; required by a stop); a ball's: "
                          "one or 3")
    l_r: Annotated[Any, checked(optional(_per_coordinate(ge=0)))] = Field(
        None, description="a number >= 0 (N m s/rad; the stop's damping beyond an end; a stop's, default 0); a "
                          "ball's: one or 3")

    @model_validator(mode="after")
    def _ordered(self) -> "_JointRange":
        lower, upper = np.broadcast_arrays(np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float))
        if not np.all(lower < upper):
            raise PydanticCustomError("rbstab_invalid", "an empty range", {
                "subkey": "upper", "found": short_repr(self.upper),
                "expected": f"a number > lower = {short_repr(self.lower)} (rad), each entry"})
        if self.kind == "stop" and self.k_r is None:
            raise PydanticCustomError("rbstab_missing", "missing", {
                "subkey": "k_r", "expected": "a number > 0 (N m/rad; the stop's stiffness beyond an end)",
                "detail": "required by a stop (range.kind: stop, the default; kind: region for an admissible region)"})
        for key in ("k_r", "l_r") if self.kind == "region" else ():
            if getattr(self, key) is not None:
                raise PydanticCustomError("rbstab_invalid", "a region's spring", {
                    "subkey": key, "found": short_repr(getattr(self, key)), "expected": f"no {key}",
                    "detail": "an admissible region (range.kind: region) pushes nothing back; a stop (kind: stop) "
                              "has a spring and damper"})
        return self


class _ChainBody(_Section):
    """One body of a chain (Table 1) and its optional ground-anchored feedback (eq 24)."""

    name: _PART = Field(description=_PART_NAME_RULE)
    mass: Annotated[Any, checked(bounded_number(gt=0))] = Field(description="a number > 0 (kg)")
    inertia: Annotated[Any, checked(_spd_matrix)] = Field(
        description="3 numbers (principal moments) or a 3x3 list of lists, symmetric positive definite (kg m^2)")
    k_t: _gain_type("k_t") = _gain("k_t")
    l_t: _gain_type("l_t") = _gain("l_t")
    saturation: _BodySaturation | None = Field(None, description=_mapping_of(_BodySaturation) + " (optional)")


class _ChainJoint(_Section):
    """One joint of a chain: the law of its point and the rotational feedback across it."""

    name: _PART = Field(description=_PART_NAME_RULE)
    parent: _PART = Field(description=f"'{GROUND_NAME}' or the name of a body listed before the child")
    parent_point: _VECTOR = Field(
        default_factory=_zero, description="3 numbers (m; inertial frame for the ground, else the parent's body "
                                           "frame from its centre of mass)")
    child: _PART = Field(description="the name of a body")
    child_point: _VECTOR = Field(
        default_factory=_zero, description="3 numbers (the point C, m, the child's body frame from its centre of "
                                           "mass)")
    # ``variant`` before the gains: their validators read it from ``info.data``.
    variant: Annotated[Any, checked(_joint_variant)] = Field(
        description=f"one of {', '.join(JOINT_VARIANTS)} (hinge: the point held, the child turned about axis; "
                    "universal: about its two axes; slide: the child's orientation held, its point moved along "
                    "axis)")
    axis: Annotated[Any, checked(optional(_axis))] = Field(
        None, description="a hinge's axis a: 3 numbers, not all zero (the parent's and the child's frames, which "
                          "it leaves fixed; normalised); only with variant hinge; a universal joint's: 2 such lists, "
                          "a_1 (the parent's frame) and a_2 (the child's frame), not parallel; a slide's: 3 numbers, "
                          "the direction its child's point moves in (the parent's frame)")
    k_r: _JOINT_GAIN = Field(None, validate_default=True, description=(
        "3 numbers (a diagonal) or a 3x3 list of lists, symmetric positive semi-definite; a hinge's: a number >= 0 "
        f"about its axis ({GAIN_UNITS['k_r']}); a slide's: along its axis (N/m)"))
    l_r: _JOINT_GAIN = Field(None, validate_default=True, description=(
        "3 numbers (a diagonal) or a 3x3 list of lists, symmetric positive semi-definite; a hinge's: a number >= 0 "
        f"about its axis ({GAIN_UNITS['l_r']}); a slide's: along its axis (N s/m)"))
    k_c: _gain_type("k_c") = _gain("k_c")
    l_c: _gain_type("l_c") = _gain("l_c")
    k_d: _gain_type("k_d") = _gain("k_d")
    l_d: _gain_type("l_d") = _gain("l_d")
    k_s: Annotated[Any, checked(optional(bounded_number(ge=0)))] = Field(
        None, validate_default=True, description="a number >= 0 (N)")
    boundary_layer: Annotated[Any, checked(bounded_number(ge=0))] = Field(
        0.0, description="a number >= 0 (m; 0 = pure sign function)")
    saturation: _JointSaturation | None = Field(None, description=_mapping_of(_JointSaturation) + " (optional)")
    theta_ref: Annotated[Any, checked(optional(_joint_angles))] = Field(
        None, description="3 numbers (rad; the reference posture Theta_ref, the relative Euler angles at which the "
                          "joint's spring K_r is relaxed); a hinge's: a number, its angle q_ref (rad; optional, "
                          "default 0); a ball's: its rotation vector (rad), the relative turn at which K_r is relaxed; "
                          "a slide's: a number, its displacement q_ref (m)")
    passive: _JointPassive | None = Field(None, description=_mapping_of(_JointPassive) + " (optional: the "
                                                            "joint's passive torque, added to N_j and never limited)")
    range: _JointRange | None = Field(None, description=_mapping_of(_JointRange) + " (optional, a hinge's: its "
                                                       "range of motion, a stop beyond either end)")

    @model_validator(mode="before")
    @classmethod
    def _no_body_gains(cls, value: Any) -> Any:
        """k_t, l_t written on a joint: they are the body's (H acts from the ground)."""
        for key in BODY_GAINS:
            if isinstance(value, Mapping) and key in value:
                raise PydanticCustomError("rbstab_invalid", "a body's gain on a joint", {
                    "subkey": key, "found": short_repr(value[key]), "expected": f"no {key} on a joint",
                    "detail": f"the ground-anchored feedback H (eq 24) is a body's: give {key} to the child body"})
        return value

    @field_validator("k_c", "l_c", "k_d", "l_d", "k_s", mode="after")
    @classmethod
    def _required_by_variant(cls, value: Any, info: ValidationInfo) -> Any:
        variant = info.data.get("variant")  # absent if the variant itself is invalid
        if value is None and variant in VARIANTS and info.field_name in VARIANTS[variant].required_gains:
            raise PydanticCustomError("rbstab_missing", "missing", {"detail": f"required by variant '{variant}'"})
        return value

    @model_validator(mode="after")
    def _fits_the_kind(self) -> "_ChainJoint":
        """A hinge's axis, and its gains, reference and torque limits as numbers about it; a
        universal joint's two axes and its numbers per coordinate (one for both, or 2); a
        ball's or a free body's as 3-vectors or 3x3 matrices, and no axis."""
        hinge, universal = self.variant in ("hinge", "slide"), self.variant == "universal"  # a slide's numbers: a
        saturation, passive = self.saturation, self.passive                              # hinge's, along its axis
        values = [("k_r", self.k_r), ("l_r", self.l_r), ("theta_ref", self.theta_ref)]
        values += [] if passive is None else [(f"passive.{k}", getattr(passive, k)) for k in ("k_r", "l_r", "theta_ref")]
        values += [] if saturation is None else [(f"saturation.{k}", getattr(saturation, k))
                                                 for k in ("torque_n", "torque_n_lower")]
        values += [] if self.range is None else [(f"range.{k}", getattr(self.range, k))
                                                 for k in ("lower", "upper", "k_r", "l_r")]
        two_axes = self.axis is not None and isinstance(self.axis[0], (list, tuple))
        if (hinge or universal) and (self.axis is None or two_axes != universal):
            raise PydanticCustomError("rbstab_missing" if self.axis is None else "rbstab_invalid", "an axis", {
                "subkey": "axis", **({} if self.axis is None else {"found": short_repr(self.axis)}),
                "expected": ("2 lists of 3 numbers, not parallel (the universal joint's axes a_1, a_2)" if universal
                             else f"3 numbers, not all zero (the {self.variant}'s axis)"),
                "detail": f"required by variant '{self.variant}'"})
        if not (hinge or universal) and self.axis is not None:
            raise PydanticCustomError("rbstab_invalid", "an axis", {
                "subkey": "axis", "found": short_repr(self.axis), "expected": "no axis",
                "detail": f"an axis is a hinge's, a universal joint's or a slide's; a '{self.variant}' joint turns "
                          "about all three"})
        if self.range is not None and self.variant not in ("hinge", "universal", "permanent", "ball", "slide"):
            raise PydanticCustomError("rbstab_invalid", "a range", {
                "subkey": "range", "found": "a range", "expected": "no range",
                "detail": f"a range is a hinge's (of its angle q), a universal joint's (of q_1, q_2), a slide's (of "
                          f"its displacement q) or a ball's (permanent: of its Euler angles Theta_j; ball: a cone of "
                          f"its turn); a '{self.variant}' joint has none"})
        if self.range is not None and self.variant == "ball":  # MJCF's cone: lower 0, upper the largest turn
            for key in ("lower", "upper", "k_r", "l_r"):
                value = getattr(self.range, key)
                if isinstance(value, (list, tuple)) or (key == "lower" and value != 0):
                    raise PydanticCustomError("rbstab_invalid", "a ball's cone", {
                        "subkey": f"range.{key}", "found": short_repr(value),
                        "expected": "0" if key == "lower" else "a number",
                        "detail": "a ball's range is a cone: the angle of its turn from the reference pose within "
                                  "[0, upper], as MJCF writes it"})
        for key, value in values:
            if value is None:
                continue
            listed = isinstance(value, (list, tuple))
            if hinge and listed:
                along = "along" if self.variant == "slide" else "about"
                raise PydanticCustomError("rbstab_invalid", f"a {self.variant}'s number", {
                    "subkey": key, "found": short_repr(value),
                    "expected": f"a number: a {self.variant}'s range is of its "
                                f"{'displacement' if self.variant == 'slide' else 'angle'} q"
                                if key.startswith("range.")
                                else f"a number: a {self.variant}'s feedback, reference and limits act {along} its "
                                     "axis"})
            if universal and listed and not _is_pair(value):
                raise PydanticCustomError("rbstab_invalid", "a universal joint's numbers", {
                    "subkey": key, "found": short_repr(value),
                    "expected": "a number (both coordinates) or 2 numbers (q_1's, q_2's)"})
            if not (hinge or universal) and _is_pair(value):
                raise PydanticCustomError("rbstab_invalid", "a universal joint's numbers", {
                    "subkey": key, "found": short_repr(value),
                    "expected": "a number or 3 numbers (2 numbers are a universal joint's, variant: universal)"})
            if not (hinge or universal or listed or key.startswith(("saturation.", "range."))):
                what = "3 numbers (rad)" if key.endswith("theta_ref") else "3 numbers (a diagonal) or a 3x3 list of lists"
                raise PydanticCustomError("rbstab_invalid", "a hinge's number", {
                    "subkey": key, "found": short_repr(value),
                    "expected": f"{what} (a single number is a hinge's, variant: hinge)"})
        bounds = None if self.range is None else tuple(
            np.broadcast_to(np.asarray(end, dtype=float), (2,) if universal else np.shape(end))
            for end in (self.range.lower, self.range.upper))
        springs = [("theta_ref", self.theta_ref, self.k_r)]
        springs += [] if passive is None else [("passive.theta_ref", passive.theta_ref, passive.k_r)]
        for key, value, stiffness in springs:  # a spring's rest angle (0 where not written) inside the range
            value = np.asarray(0.0 if value is None else value, dtype=float)
            if self.variant == "ball":  # its cone bounds the turn's angle |Theta_ref|
                value = np.linalg.norm(value)
            if (bounds is not None and np.any(np.asarray(stiffness or 0.0) != 0)
                    and not np.all((bounds[0] <= value) & (value <= bounds[1]))):
                raise PydanticCustomError("rbstab_invalid", "a reference beyond the range", {
                    "subkey": key, "found": short_repr(value.tolist()),
                    "expected": within_range(bounds),
                    "detail": "the spring would be relaxed where the stop pushes back" if self.range.kind == "stop"
                              else "the spring would be relaxed outside the admissible region"})
        return self

    @model_validator(mode="after")
    def _saturation_fits_the_variant(self) -> "_ChainJoint":
        """A limit of Lambda_j where Lambda_j is no actuator's (as for ``controller``)."""
        limit = None if self.saturation is None else self.saturation.constraint_force
        if limit is None:
            return self
        if point_fixed(self.variant) or (self.variant == "sliding" and float(self.boundary_layer) == 0.0):
            raise PydanticCustomError("rbstab_invalid", "limit on the pin", {
                "subkey": "saturation.constraint_force", "found": short_repr(limit),
                "expected": f"no limit with variant '{self.variant}'" if point_fixed(self.variant) else
                            "no limit with the pure sign law (boundary_layer: 0)",
                "detail": "a slide's force along its axis is limited by saturation.torque_n (N), its feedback's "
                          "limit as for a hinge; Lambda_j is its reaction" if self.variant == "slide" else
                          "Lambda is then the pin's reaction or K_s sgn(E), not an actuator's force"})
        return self


class _ChainDisturbance(_Disturbance):
    """One disturbance on one body of a chain."""

    body: Annotated[Any, checked(optional(part_name))] = Field(
        None, description="the name of the body it acts on (optional with one body)")


def _chain_error(key: str, found: str, expected: str, detail: str = "") -> PydanticCustomError:
    ctx = {"key": key, "found": found, "expected": expected}
    if detail:
        ctx["detail"] = detail
    return PydanticCustomError("rbstab_invalid", "invalid chain", ctx)


def _names_list(names: Sequence[str]) -> str:
    return ", ".join(f"'{n}'" for n in names)


class ChainSchema(_Run):
    """A chain configuration (pydantic model; the public result is
    :class:`rbstab.config.RunConfig`): 1 to :data:`rbstab.chain.MAX_BODIES` bodies,
    each held by exactly one joint to the ground or to a body listed before it (a tree)."""

    name: Annotated[Any, checked(run_name)] = Field(
        description="a name of letters, digits, '_', '.' and '-' (it becomes a file name)")
    gravity: _VECTOR = Field(default_factory=_zero, description="3 numbers (g, inertial frame, m/s^2)")
    bodies: list[_ChainBody] = Field(
        description=f"a list of 1 to {MAX_BODIES} bodies, each {_mapping_of(_ChainBody)}")
    joints: list[_ChainJoint] = Field(
        description=f"a list of joints, one per body, each {_mapping_of(_ChainJoint)}")
    initial_state: dict[str, _ChainInitialState] = Field(
        default_factory=dict, description=f"a mapping of body names to {_mapping_of(_ChainInitialState)}")
    simulation: _Simulation = Field(
        default_factory=_Simulation, validate_default=True, description=_mapping_of(_Simulation))
    disturbances: list[_ChainDisturbance] | None = Field(
        None, description=f"a list of at most {MAX_DISTURBANCES} disturbances, each "
                          f"{_mapping_of(_ChainDisturbance)} (optional; docs/disturbances.md)")

    @field_validator("bodies", mode="before")
    @classmethod
    def _few_bodies(cls, value: Any) -> Any:
        if isinstance(value, (list, tuple)) and not 1 <= len(value) <= MAX_BODIES:
            raise PydanticCustomError("rbstab_invalid", "too many bodies", {
                "key": "bodies", "found": f"{len(value)} bodies",
                "expected": f"a list of 1 to {MAX_BODIES} bodies (the most one chain holds)"})
        return value

    @field_validator("initial_state", mode="before")
    @classmethod
    def _by_body(cls, value: Any, info: ValidationInfo) -> Any:
        """A one-body ``initial_state`` (theta, omega, ... at its top) in a chain."""
        blocks = set(InitialStateSchema.model_fields)
        if isinstance(value, Mapping) and value and set(value) <= blocks:
            names = [b.name for b in info.data.get("bodies") or ()]
            if not blocks & set(names):
                raise PydanticCustomError("rbstab_invalid", "one-body initial state", {
                    "key": "initial_state", "found": f"keys {', '.join(map(str, value))}",
                    "expected": "body names as keys" + (f" ({_names_list(names)})" if names else "")
                                + f", each {_mapping_of(InitialStateSchema)}",
                    "detail": "a chain's initial state is given per body"})
        return value

    @model_validator(mode="after")
    def _a_tree(self) -> "ChainSchema":
        """Distinct names; every body held by exactly one joint whose parent is the ground or
        a body listed before its child (so no loop)."""
        bodies = [b.name for b in self.bodies]
        index = {name: bodies.index(name) for name in bodies}
        for i, name in enumerate(bodies):
            if name == GROUND_NAME:
                raise _chain_error(f"bodies.{i}.name", short_repr(name), f"a name other than '{GROUND_NAME}'",
                                   f"'{GROUND_NAME}' is the parent of the joints to the inertial frame")
            if index[name] != i:
                raise _chain_error(f"bodies.{i}.name", short_repr(name), "a name no other body has",
                                   f"bodies.{bodies.index(name)}.name is '{name}' too")
        joints = [j.name for j in self.joints]
        for i, name in enumerate(joints):
            if joints.index(name) != i:
                raise _chain_error(f"joints.{i}.name", short_repr(name), "a name no other joint has",
                                   f"joints.{joints.index(name)}.name is '{name}' too")
        holder: dict[str, int] = {}
        for i, joint in enumerate(self.joints):
            if joint.child not in index:
                hint = _did_you_mean(joint.child, bodies)
                raise _chain_error(f"joints.{i}.child", short_repr(joint.child),
                                   f"the name of a body: {_names_list(bodies)}", hint)
            if joint.parent != GROUND_NAME and joint.parent not in index:
                hint = _did_you_mean(joint.parent, [GROUND_NAME, *bodies])
                raise _chain_error(f"joints.{i}.parent", short_repr(joint.parent),
                                   f"'{GROUND_NAME}' or the name of a body: {_names_list(bodies)}", hint)
            if joint.child in holder:
                k = holder[joint.child]
                raise _chain_error(f"joints.{i}.child", short_repr(joint.child), "a body no other joint holds",
                                   f"joint '{self.joints[k].name}' (joints.{k}) holds '{joint.child}' already; "
                                   "every body has exactly one joint")
            holder[joint.child] = i
        for i, name in enumerate(bodies):
            if name not in holder:
                raise _chain_error("joints", f"{len(joints)} joints ({_names_list(joints)})",
                                   "exactly one joint per body",
                                   f"body '{name}' (bodies.{i}) has none: add a joint with child: {name}")
        parent_of = {j.child: j.parent for j in self.joints}
        for i, joint in enumerate(self.joints):  # a loop, before the order: it is the graver fault
            path, at = [joint.child], joint.parent
            while at != GROUND_NAME and at not in path:
                path.append(at)
                at = parent_of[at]
            if at == joint.child:  # reported once, by a joint of the loop
                loop = " -> ".join([*path[path.index(at):], at][::-1])
                raise _chain_error(f"joints.{i}.parent", short_repr(joint.parent),
                                   f"'{GROUND_NAME}' or a body listed before '{joint.child}'",
                                   f"a loop: {loop}; a chain is a tree, each body held by one joint from the "
                                   f"ground or from a body nearer the ground")
        for i, joint in enumerate(self.joints):
            if joint.parent != GROUND_NAME and index[joint.parent] > index[joint.child]:
                earlier = bodies[: index[joint.child]]
                raise _chain_error(f"joints.{i}.parent", short_repr(joint.parent),
                                   f"'{GROUND_NAME}' or a body listed before '{joint.child}' in bodies"
                                   + (f": {_names_list(earlier)}" if earlier else ""),
                                   f"bodies are listed parents first: list '{joint.parent}' before "
                                   f"'{joint.child}'")
        return self

    @model_validator(mode="after")
    def _names_known(self) -> "ChainSchema":
        """Every body named in ``initial_state`` and ``disturbances`` is one of ``bodies``."""
        bodies = [b.name for b in self.bodies]
        for name in self.initial_state:
            if name not in bodies:
                raise _chain_error(f"initial_state.{name}", short_repr(name),
                                   f"the name of a body: {_names_list(bodies)}",
                                   _did_you_mean(str(name), bodies, "initial_state."))
        for i, d in enumerate(self.disturbances or ()):
            if d.body is None and len(bodies) > 1:
                raise _chain_error(f"disturbances.{i}.body", "nothing",
                                   f"the name of the body it acts on: {_names_list(bodies)}")
            if d.body is not None and d.body not in bodies:
                raise _chain_error(f"disturbances.{i}.body", short_repr(d.body),
                                   f"the name of a body: {_names_list(bodies)}", _did_you_mean(d.body, bodies))
        return self

    @model_validator(mode="after")
    def _fits_the_run(self) -> "ChainSchema":
        """As for a one-body config: disturbances start by t_end and not with the pure sign
        law; a bound of E needs a joint that is not pinned; each body clear of gimbal lock."""
        sign_law = [j.name for j in self.joints if j.variant == "sliding" and float(j.boundary_layer) == 0.0]
        for i, d in enumerate(self.disturbances or ()):
            if not starts_in_run(float(d.start), float(self.simulation.t_end)):
                raise _chain_error(f"disturbances.{i}.start", short_repr(d.start),
                                   f"a number in [0, simulation.t_end] = [0, {float(self.simulation.t_end):g}] (s)")
            if sign_law:
                raise _chain_error(f"disturbances.{i}", f"kind '{d.kind}'",
                                   "no disturbances with the pure sign law (boundary_layer: 0)",
                                   f"joint '{sign_law[0]}' has it; give it a boundary layer > 0")
        limits = self.simulation.limits
        if (limits is not None and limits.constraint_error is not None
                and all(point_fixed(j.variant) for j in self.joints)):
            raise _chain_error("simulation.limits.constraint_error", short_repr(limits.constraint_error),
                               "no bound when every joint is 'permanent'",
                               "their points are pinned: E = 0 at every instant")
        turned = {j.child: j.variant for j in self.joints if j.variant in AXES_VARIANTS}
        for name, state in self.initial_state.items():  # a hinge's child: its q, u; any other body: its blocks
            given = state.model_fields_set & (set(HINGE_STATE) if name not in turned else set(INITIAL_STATE_BLOCKS))
            for key in sorted(given):
                kind = {"universal": "universal joint", "slide": "slide"}.get(turned.get(name), "hinge")
                what = "q (m) and u (m/s), its slide's displacement and rate" if kind == "slide" else \
                    f"q (rad) and u (rad/s), its {kind}'s angle and rate"
                raise _chain_error(f"initial_state.{name}.{key}", short_repr(getattr(state, key)),
                                   (what if name in turned else
                                    f"{', '.join(INITIAL_STATE_BLOCKS)}: the blocks of its state"),
                                   (f"'{name}' is a {kind}'s child; its {kind} places and turns it" if name in turned
                                    else f"'{name}' is not a hinge's child"))
            for key in ("q", "u") if name in turned else ():
                value = getattr(state, key)
                if value is not None and _is_pair(value) != (turned[name] == "universal"):
                    raise _chain_error(f"initial_state.{name}.{key}", short_repr(value),
                                       "2 numbers (a universal joint's q_1, q_2)" if turned[name] == "universal"
                                       else "a number (a hinge's angle)" if turned[name] == "hinge"
                                       else "a number (a slide's displacement, m)",
                                       f"'{name}' is a {turned[name]} joint's child")
                turns = np.asarray(0.0 if value is None else value, dtype=float)
                if key == "q" and turned[name] != "slide" and not np.all(np.abs(turns) < math.pi):
                    raise _chain_error(f"initial_state.{name}.q", short_repr(value),
                                       "a number in (-pi, pi) (rad)" if turns.ndim == 0 else
                                       "2 numbers, each in (-pi, pi) (rad)",
                                       f"'{name}' is a {turned[name]} joint's child")
        for j in self.joints:  # a start inside the admissible region of its range
            if j.variant not in AXES_VARIANTS or j.range is None or j.range.kind != "region":
                continue
            state = self.initial_state.get(j.child)
            q = np.asarray(0.0 if state is None or state.q is None else state.q, dtype=float)
            bounds = tuple(np.broadcast_to(np.asarray(end, dtype=float), (2,) if j.variant == "universal" else ())
                           for end in (j.range.lower, j.range.upper))
            if not np.all((bounds[0] <= q) & (q <= bounds[1])):
                lower, upper = np.broadcast_arrays(*bounds)
                raise _chain_error(f"initial_state.{j.child}.q", short_repr(q.tolist()),
                                   f"an angle in joints.{j.name}.range [{float(lower):g}, {float(upper):g}] (rad)"
                                   if lower.ndim == 0 else f"angles in joints.{j.name}.range: "
                                   + within_range(bounds).removeprefix("angles in the range "),
                                   f"the range of joint '{j.name}' is an admissible region (kind: region), and the "
                                   "run would start outside it")
        margin = float(self.simulation.gimbal_margin)
        angles = [(f"initial_state.{name}.theta", state.theta) for name, state in self.initial_state.items()]
        angles += [(f"joints.{j.name}.theta_ref", j.theta_ref) for j in self.joints
                   if j.theta_ref is not None and j.variant not in (*AXES_VARIANTS, "ball")]
        angles += [(f"joints.{j.name}.passive.theta_ref", j.passive.theta_ref) for j in self.joints
                   if j.passive is not None and j.passive.theta_ref is not None
                   and j.variant not in (*AXES_VARIANTS, "ball")]
        for key, theta in angles:
            if not clear_of_gimbal_lock(theta[1], margin):
                limit = math.pi / 2 - margin
                raise _chain_error(key, short_repr(theta),
                                   "3 numbers (rad) with theta_2 in (-pi/2 + gimbal_margin, pi/2 - gimbal_margin) "
                                   f"= ({-limit:.6g}, {limit:.6g})",
                                   f"B(theta) is singular at |theta_2| = pi/2 (gimbal lock, eq 1); "
                                   f"gimbal_margin = {margin:g}")
        return self


#: The top-level keys of a chain configuration.
CHAIN_TOP_LEVEL = _mapping_of(ChainSchema)


_SECTIONS = tuple(RunSchema.model_fields)
TOP_LEVEL = _mapping_of(RunSchema)


def submodel(annotation: Any) -> type[BaseModel] | None:
    """The model of a field that is a section (``_Saturation`` or ``_Saturation | None``)."""
    for candidate in (annotation, *typing.get_args(annotation)):
        if isinstance(candidate, type) and issubclass(candidate, BaseModel):
            return candidate
    return None


def list_model(annotation: Any) -> type[BaseModel] | None:
    """The model of the entries of a field that is a list of sections (``disturbances``)."""
    for candidate in (annotation, *typing.get_args(annotation)):
        if typing.get_origin(candidate) is list:
            return submodel(typing.get_args(candidate)[0])
    return None


def mapping_model(annotation: Any) -> type[BaseModel] | None:
    """The model of the values of a field that maps names to sections (a chain's
    ``initial_state``: body name -> state)."""
    for candidate in (annotation, *typing.get_args(annotation)):
        if typing.get_origin(candidate) is dict:
            return submodel(typing.get_args(candidate)[1])
    return None


def field_check(info: Any) -> Callable[[Any], Any] | None:
    """The check a field is validated with (its ``rule`` and ``shape`` attributes say what
    a batched check and a key path read of it), or None (a section, a list of sections)."""
    return next((m.func for m in getattr(info, "metadata", ()) if isinstance(m, BeforeValidator)), None)


# -- pydantic errors -> our lines ----------------------------------------------------------


def short_repr(value: Any, limit: int = 80) -> str:
    """Short YAML-flavoured repr of a found value, truncated to ``limit`` characters."""

    def rep(v: Any, depth: int = 0) -> str:
        if v is None:
            return "null"
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, np.ndarray):
            v = v.tolist()
        if isinstance(v, np.generic):
            v = v.item()
        if depth > 3:
            return "..."
        if isinstance(v, (list, tuple)):
            items = [rep(x, depth + 1) for x in v[:10]] + (["..."] if len(v) > 10 else [])
            return "[" + ", ".join(items) + "]"
        if isinstance(v, Mapping):
            items = [f"{rep(k, depth + 1)}: {rep(x, depth + 1)}" for k, x in list(v.items())[:10]]
            return "{" + ", ".join(items + (["..."] if len(v) > 10 else [])) + "}"
        return repr(v)

    text = rep(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def field_at(loc: Sequence[Any], root: type[BaseModel] | None = None) -> tuple[type[BaseModel] | None, Any]:
    """(model holding the last key of ``loc``, FieldInfo of that key or None).

    ``root`` is the model ``loc`` starts in (default :class:`RunSchema`). A ``dict``
    field's keys are free: the part after it names an entry, and the walk goes on in the
    model of its values (``random.params.<key>.uniform``).
    """
    model: type[BaseModel] | None = RunSchema if root is None else root
    parts = list(loc)
    i = 0
    while i < len(parts):
        part = parts[i]
        if model is None or part not in model.model_fields:
            return (model if i == len(parts) - 1 else None), None
        info = model.model_fields[part]
        if i == len(parts) - 1:
            return model, info
        ann = info.annotation
        if typing.get_origin(ann) is dict:  # skip the entry's key
            ann = typing.get_args(ann)[1]
            i += 1
            if i == len(parts) - 1:
                return None, info
        if typing.get_origin(ann) in (typing.Union, types.UnionType):  # Optional[Model]
            ann = next((a for a in typing.get_args(ann) if a is not type(None)), None)
        if typing.get_origin(ann) is list:  # skip the entry's index
            ann = typing.get_args(ann)[0]
            i += 1
            if i == len(parts) - 1:
                return None, info
        model = ann if isinstance(ann, type) and issubclass(ann, BaseModel) else None
        i += 1
    return None, None


def _other_section_hint(key: str, section: str) -> str:
    for name in _SECTIONS:
        ann = RunSchema.model_fields[name].annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel) and name != section:
            if key in ann.model_fields:
                return f"did you mean '{name}.{key}'?"
    return ""


def problem_line(
    err: Mapping[str, Any], name_defaulted: bool, *, root: type[BaseModel] | None = None, what: str = "config key"
) -> tuple[str, str]:
    """(dotted key, message line) for one pydantic error.

    ``root`` is the validated model (default :class:`RunSchema`; the sweep spec passes
    its own) and ``what`` the line's first words (``"sweep key"`` for a spec).
    """
    loc = tuple(part for part in err["loc"] if part != "[key]")  # a dict key's own error
    ctx = err.get("ctx") or {}
    key = ctx.get("key") or ".".join(str(p) for p in loc)
    if ctx.get("subkey"):  # a key inside the entry a model's validator checked
        key = ".".join(str(p) for p in (*loc, ctx["subkey"]))
    model, info = field_at(loc, root)
    expected = ctx.get("expected") or (info.description if info is not None else None) or ""
    detail = ctx.get("detail", "")
    head = f"{what} '{key}'"
    if ctx.get("line"):  # a refusal that is its own line (a key path that names nothing)
        return key, f"{what} {key!r}: {ctx['line']}"  # repr: a key with a line break stays on one line

    if err["type"] in ("extra_forbidden", "invalid_key"):
        allowed = list(model.model_fields) if model is not None else []
        word = str(loc[-1])
        section = str(loc[-2]) if len(loc) > 1 else ""
        if len(loc) > 2 and isinstance(loc[-2], int):  # an entry of a list: name the list too
            section = f"{loc[-3]}.{section}"
        # a key of another section spelled exactly is surely meant; else the closest here
        other = _other_section_hint(word, section) if root is None or root is RunSchema else ""
        hint = other or _did_you_mean(word, allowed, f"{section}." if section else "")
        hint = f"; {hint}" if hint else ""
        return key, f"{head}: unknown key{hint} (allowed: {', '.join(allowed)})"
    if err["type"] in ("missing", "rbstab_missing"):
        text = f"{head}: missing; expected {expected}"
        return key, text + (f" ({detail})" if detail else "")
    found = ctx.get("found") or short_repr(err.get("input"))
    if not expected:  # a pydantic error this module does not anticipate
        expected, detail = "a valid value", err.get("msg", "")
    if err["type"] == "model_type" and not detail:
        detail = f"{kind_of(err.get('input'))}, not a mapping"
    if key == "name" and name_defaulted:
        detail = "; ".join(filter(None, [detail, "the default name; set 'name:' in the config"]))
    text = f"{head}: found {found}; expected {expected}"
    return key, text + (f" ({detail})" if detail else "")
