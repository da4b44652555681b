"""Many runs as one batch of arrays: what an engine needs to integrate them, built from a table.

A sweep's runs are a table (:class:`rbstab.sweep.table.RunTable`): a few validated resolved
configurations (*templates*) and, per run, its template and the values of the varied dotted
keys. :func:`batch_from_table` turns a table (or a slice of one) into a :class:`RunBatch`
with vectorised numpy: one :data:`rbstab.model.PARAMETERS` record per run (the derived
fields J^-1, J_p and J_p^-1, G and L_d^-1 by batched ``numpy.linalg``), the initial states,
the variant codes and the integration settings (:data:`rbstab.engine.settings.SETTINGS`).
No configuration object is made per run; the records are bit for bit those of
:func:`rbstab.model.parameters` for each run's validated configuration.

A batch depends on no integrator: the compiled CPU engine
(:func:`rbstab.simulator.simulate_batch`) and any other engine take its arrays as they are.

One part is computed run by run: the constant h of v (``lyapunov_offset``) of a body under
gravity, which is the minimum of a stored energy found by ``scipy.optimize`` (once per
distinct parameter record; a sweep over initial states computes it once). Without gravity
h is 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..config import GAIN_NAMES, INITIAL_STATE_BLOCKS
from ..config.paths import parse_key
from ..layout import LIMITED, STATE_SIZE, VARIANT_CODES, VARIANT_LAYOUTS
from ..model import DISTURBANCE_KINDS, DISTURBANCE_QUANTITIES, PARAMETERS, SATURATION_SHAPES, set_limits
from ..variants import VARIANTS
from ..variants.registry import record_offset
from .settings import SETTING_COLUMNS, SETTINGS, settings_rows
from .tableaus import METHODS

__all__ = ["RunBatch", "batch_from_table", "MAX_STATE", "NOT_COMPILED"]

#: The largest state of any variant (the second axis of :attr:`RunBatch.y0`).
MAX_STATE = max(STATE_SIZE)
#: ``RunBatch.settings["method"]`` of a run whose method is not one of
#: :data:`rbstab.engine.METHODS` (Radau, BDF, LSODA: integrated by scipy).
NOT_COMPILED = -1


@dataclass(frozen=True)
class RunBatch:
    """n runs as arrays (module docstring); every field has the run axis first.

    Attributes
    ----------
    params : ndarray of :data:`rbstab.model.PARAMETERS`, shape (n,)
        Each run's physical parameters (SI units; body quantities in the body frame,
        gravity and the weight in the inertial frame); gains a variant does not use are 0.
    y0 : ndarray of float64, shape (n, MAX_STATE)
        Initial states: the first ``n_state[i]`` entries of row i are the state of run i in
        its variant's layout (:data:`rbstab.layout.VARIANT_LAYOUTS`: theta [rad], omega
        [rad/s] (body frame), position X [m], velocity V [m/s], controller state D [m]),
        the rest 0.
    n_state : ndarray of int64, shape (n,)
        State size of each run (6, 12 or 15).
    variant : ndarray of int64, shape (n,)
        Variant code of each run (:data:`rbstab.layout.VARIANT_CODES`).
    settings : ndarray of :data:`rbstab.engine.settings.SETTINGS`, shape (n,)
        t_end [s], rtol, atol, max_step [s] (inf: none), gimbal_margin [rad], max_steps,
        max_wall_time [s] (inf: none) and method (its index in
        :data:`rbstab.engine.METHODS`, :data:`NOT_COMPILED` for another).
    n_samples : ndarray of int64, shape (n,)
        Output samples of each run, evenly spaced on [0, t_end].
    compiled : ndarray of bool, shape (n,)
        Whether a compiled engine integrates the run: its method is one of
        :data:`rbstab.engine.METHODS` and it is not the pure sign law of ``sliding``
        (``boundary_layer`` 0, integrated by :mod:`rbstab.engine.switching`).
    """

    params: np.ndarray
    y0: np.ndarray
    n_state: np.ndarray
    variant: np.ndarray
    settings: np.ndarray
    n_samples: np.ndarray
    compiled: np.ndarray

    def __len__(self) -> int:
        return len(self.params)

    def settings_rows(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The settings of ``rows`` as floats, shape (k, 7): t_end, rtol, atol, max_step,
        gimbal_margin, max_steps, max_wall_time (what
        :func:`rbstab.engine.integrate_runs` takes)."""
        return settings_rows(self.settings[rows])


class _Fields:
    """Each run's value of every numeric field the batch reads, as written (a 3-list stays
    shape (3,)), from the templates and the varied keys (:func:`batch_from_table`)."""

    def __init__(self, templates: Sequence[Mapping], keys: Sequence[str], columns: Mapping[str, np.ndarray],
                 template: np.ndarray) -> None:
        self.templates, self.template, self.n = templates, np.asarray(template), len(template)
        present = np.unique(self.template)
        # (template, its runs) of each template the runs use
        self.groups = [(int(t), np.flatnonzero(self.template == t)) if len(present) > 1 else (int(t), np.arange(self.n))
                       for t in present]
        self.varied: dict[tuple[str, str], list[tuple[tuple[int, ...], np.ndarray]]] = {}
        for key in keys:
            if "." not in key or columns[key].dtype == object:
                continue  # a template's own value (runs share a template's non-numeric values)
            path = parse_key(key)
            self.varied.setdefault((path.section, path.name), []).append((path.index, columns[key]))

    def get(self, section: str, name: str, default=None, *, shape: tuple | None = None) -> np.ndarray:
        """The field of every run (``name`` dotted inside a subsection), shape (n, *shape):
        ``shape`` (3, 3) makes a matrix of a 3-list (its diagonal), as the configuration's
        loader does, and (3,) 3 numbers of one; ``default`` for a template without the field
        (None: a ValueError)."""
        out = None
        for t, rows in self.groups:
            written = parse_key(f"{section}.{name}").get(self.templates[t], None)
            if written is None:
                if default is None:
                    raise ValueError(f"no {section}.{name} in template {int(t)}")
                written = default
            written_shape = (3,) if shape == (3,) else np.shape(written)
            value = np.broadcast_to(np.array(written, dtype=float), (len(rows), *written_shape)).copy()
            for index, column in self.varied.get((section, name), ()):
                part = np.asarray(column[rows], dtype=float)
                if shape == (3,) and not index and part.ndim == 1:
                    part = np.broadcast_to(part[:, None], (len(rows), 3))
                if index:
                    value[(slice(None), *index)] = part
                else:
                    value = part.copy()
            if shape == (3, 3) and value.ndim == 2:  # 3 numbers: a diagonal
                value = value[:, :, None] * np.eye(3)
            if out is None:
                out = np.empty((self.n, *value.shape[1:]))
            out[rows] = value
        return out

    def text(self, section: str, name: str) -> np.ndarray:
        """A template's text field (``controller.variant``, ``simulation.method``) of every run."""
        return self.of_templates([t[section][name] for t in self.templates], dtype=object)

    def of_templates(self, values: Sequence, dtype=None) -> np.ndarray:
        """Each run's entry of ``values`` (a value a template)."""
        return np.asarray(values, dtype=dtype)[self.template]


def _inverse(matrices: np.ndarray) -> np.ndarray:
    """``numpy.linalg.inv`` of each 3x3 matrix (one LAPACK call per matrix, as for one)."""
    return np.linalg.inv(matrices) if len(matrices) else matrices.copy()


def _hat(r: np.ndarray) -> np.ndarray:
    """:func:`rbstab.kinematics.hat` of each row of ``r`` (n, 3): shape (n, 3, 3)."""
    out = np.zeros(r.shape + (3,))
    x, y, z = r[:, 0], r[:, 1], r[:, 2]
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 0] = -z, y, z
    out[:, 1, 2], out[:, 2, 0], out[:, 2, 1] = -x, -y, x
    return out


def batch_from_table(templates: Sequence[Mapping], keys: Sequence[str], columns: Mapping[str, np.ndarray],
                     template: np.ndarray, *, timeout: float | None = None) -> RunBatch:
    """The :class:`RunBatch` of n runs given as a table.

    Parameters
    ----------
    templates : sequence of mapping
        Validated resolved configurations (``RunConfig.resolved``; ``name`` ignored).
    keys : sequence of str
        Dotted config keys set on a run's template, in order (``body.mass``,
        ``controller.k_c``, ``controller.k_c.0``, ``initial_state.omega`` ...); keys of
        non-numeric values (object columns) are their template's own.
    columns : mapping of str to ndarray
        key -> the runs' values, shape (n, ...).
    template : array_like of int, shape (n,)
        Each run's template.
    timeout : float, optional
        Wall-time limit of every run [s], instead of ``simulation.max_wall_time``.

    Returns
    -------
    RunBatch
        ``params[i]`` equals, bit for bit, :func:`rbstab.model.parameters` of run i's
        validated configuration with its ``lyapunov_offset``.

    Raises
    ------
    ValueError
        If a key does not fit its template's value (a configuration the sweep's validation
        would have refused), or a template lacks a field.
    """
    f = _Fields(templates, keys, columns, np.asarray(template, dtype=np.int64))
    n = f.n
    if n == 0:
        return RunBatch(np.zeros(0, PARAMETERS), np.zeros((0, MAX_STATE)), np.zeros(0, np.int64),
                        np.zeros(0, np.int64), np.zeros(0, SETTINGS), np.zeros(0, np.int64), np.zeros(0, bool))
    names = f.text("controller", "variant")
    code = f.of_templates([VARIANT_CODES[t["controller"]["variant"]] for t in templates], dtype=np.int64)
    used = {g: np.isin(names, [v for v, cls in VARIANTS.items() if g in cls.required_gains])
            for g in (*GAIN_NAMES, "k_s")}
    p = np.zeros(n, dtype=PARAMETERS)
    mass = f.get("body", "mass")
    inertia = f.get("body", "inertia", shape=(3, 3))
    r = f.get("body", "attachment_point")
    gravity = f.get("body", "gravity")
    p["mass"], p["inertia"], p["attachment_point"] = mass, inertia, r
    p["inertia_inv"] = _inverse(inertia)
    r_hat = _hat(r)
    p["pivot_inertia"] = pivot = inertia - (mass[:, None, None] * r_hat) @ r_hat
    p["pivot_inertia_inv"] = _inverse(pivot)
    p["weight"] = mass[:, None] * gravity
    for g in GAIN_NAMES:
        rows = np.flatnonzero(used[g])
        if len(rows):
            p[g][rows] = f.get("controller", g, [0.0, 0.0, 0.0], shape=(3, 3))[rows]
    rows = np.flatnonzero(used["l_d"])
    p["l_d_inv"][rows] = _inverse(p["l_d"][rows])
    sliding = used["k_s"]
    if sliding.any():
        p["k_s"][sliding] = f.get("controller", "k_s", 0.0)[sliding]
        p["boundary_layer"][sliding] = f.get("controller", "boundary_layer", 0.0)[sliding]
    shapes = f.of_templates([SATURATION_SHAPES[t["controller"]["saturation"].get("shape", "clip")]
                             if t["controller"].get("saturation") else 0 for t in templates], dtype=float)
    saturated = np.flatnonzero(shapes > 0)
    if len(saturated):
        p["saturation"] = shapes
        for field, key in (("torque_limit", "torque_n"), ("force_limit", "force_h"),
                           ("constraint_force_limit", "constraint_force")):
            p[field][saturated] = f.get("controller", f"saturation.{key}", math.inf, shape=(3,))[saturated]
    _disturbances(p, f, templates)
    _limits(p, f, templates)
    p["lyapunov_offset"] = _offsets(p, names, gravity)
    settings = np.zeros(n, dtype=SETTINGS)
    for name in SETTING_COLUMNS:
        value = f.get("simulation", name, np.inf) if name in ("max_step", "max_wall_time") else f.get("simulation", name)
        settings[name] = value
    if timeout is not None:
        settings["max_wall_time"] = float(timeout)
    settings["method"] = f.of_templates([METHODS.index(m) if m in METHODS else NOT_COMPILED
                                         for m in (t["simulation"]["method"] for t in templates)])
    sign_law = sliding & (p["boundary_layer"] == 0)
    return RunBatch(params=p, y0=_initial_states(f, code), n_state=np.asarray(STATE_SIZE, dtype=np.int64)[code],
                    variant=code, settings=settings, n_samples=f.get("simulation", "n_samples").astype(np.int64),
                    compiled=(settings["method"] != NOT_COMPILED) & ~sign_law)


def _disturbances(p: np.ndarray, f: _Fields, templates: Sequence[Mapping]) -> None:
    """The disturbances' fields of every run (:func:`rbstab.model.set_disturbances`): the
    entries of its template, each number as written there or in a column
    (``disturbances.0.value.1``)."""
    lists = [t.get("disturbances") or () for t in templates]
    count = f.of_templates([len(d) for d in lists], dtype=float)
    if not count.any():
        return
    p["disturbance_count"] = count
    for i in range(int(count.max())):
        entry = [d[i] if i < len(d) else None for d in lists]
        rows = np.flatnonzero(count > i)
        p["disturbance_kind"][:, i] = f.of_templates([DISTURBANCE_KINDS[e["kind"]] if e else 0 for e in entry],
                                                    dtype=float)
        p["disturbance_torque"][:, i] = f.of_templates(
            [DISTURBANCE_QUANTITIES[e.get("quantity", "force")] if e else 0 for e in entry], dtype=float)
        noise = f.of_templates([bool(e) and e["kind"] == "noise" for e in entry], dtype=bool)
        value = f.get("disturbances", f"{i}.value", [0.0, 0.0, 0.0], shape=(3,))
        rms = f.get("disturbances", f"{i}.rms", [0.0, 0.0, 0.0], shape=(3,))
        p["disturbance_value"][rows, i] = np.where(noise[:, None], rms, value)[rows]
        p["disturbance_point"][rows, i] = f.get("disturbances", f"{i}.point", [0.0, 0.0, 0.0], shape=(3,))[rows]
        for field, default in (("start", 0.0), ("duration", 0.0), ("frequency", 0.0), ("phase", 0.0), ("seed", 0.0)):
            p[f"disturbance_{field}"][rows, i] = f.get("disturbances", f"{i}.{field}", default)[rows]
        p["disturbance_band"][rows, i] = f.get("disturbances", f"{i}.band", [0.0, 0.0])[rows]


def _limits(p: np.ndarray, f: _Fields, templates: Sequence[Mapping]) -> None:
    """The admissible region of every run (:func:`rbstab.model.set_limits`): each bound of
    its template's ``simulation.limits`` as written there or in a column
    (``simulation.limits.theta.1``), inf where absent."""
    bounded = f.of_templates([bool(t["simulation"].get("limits")) for t in templates], dtype=bool)
    if not bounded.any():
        set_limits(p, None)
        return
    set_limits(p, np.stack([np.where(bounded[:, None], f.get("simulation", f"limits.{name}", math.inf, shape=(3,)),
                                     np.inf) for name in LIMITED], axis=1))


def _initial_states(f: _Fields, code: np.ndarray) -> np.ndarray:
    """The runs' initial states, zero-padded to :data:`MAX_STATE` (:attr:`RunBatch.y0`)."""
    blocks = {block: f.get("initial_state", key, [0.0, 0.0, 0.0]) for key, block in INITIAL_STATE_BLOCKS.items()}
    y0 = np.zeros((f.n, MAX_STATE))
    for c, layout in enumerate(VARIANT_LAYOUTS.values()):
        rows = np.flatnonzero(code == c)
        if len(rows):
            y0[rows, : layout.size] = np.concatenate([blocks[b][rows] for b in layout.blocks], axis=1)
    return y0


def _offsets(p: np.ndarray, names: np.ndarray, gravity: np.ndarray) -> np.ndarray:
    """h [J] of each run (``Variant.lyapunov_offset``): 0 without gravity, else the
    variant's equilibrium, once per distinct record."""
    out = np.zeros(len(p))
    heavy = np.flatnonzero(np.any(p["weight"] != 0, axis=1))
    if not len(heavy):
        return out
    keys = np.array([p[i].tobytes() + gravity[i].tobytes() + names[i].encode() for i in heavy], dtype=object)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    found = np.array([record_offset(p[heavy[i]], gravity[heavy[i]], names[heavy[i]]) for i in first])
    out[heavy] = found[inverse.ravel()]
    return out
