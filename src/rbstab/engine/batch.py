"""Many runs as one batch of arrays: what an engine needs to integrate them, built from a table.

A sweep's runs are a table (:class:`rbstab.sweep.table.RunTable`): a few validated resolved
configurations (*templates*) and, per run, its template and the values of the varied dotted
keys. :func:`batch_from_table` turns a table (or a slice of one) into a :class:`RunBatch`
with vectorised numpy: each run a tree of bodies (one body: its one-body tree), one
:data:`rbstab.model.PARAMETERS` record per body and joint (the derived fields J^-1, J_p and
J_p^-1, G and L_d^-1 by batched ``numpy.linalg``), the initial states and the integration
settings (:data:`rbstab.engine.settings.SETTINGS`). No configuration object is made per
run; the records are bit for bit those of the runs' validated configurations.
:func:`batch_of` makes the same batch of validated configurations.

A batch depends on no integrator: the compiled CPU engine
(:func:`rbstab.simulator.simulate_batch`) and any other engine take its arrays as they are.

One part is computed per distinct tree, not per run: the constant h of v (its rest state's
stored energy, ``scipy.optimize``; a sweep over initial states computes it once). Without
gravity h is 0.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..chain import hinge_vectors
from ..config.loader import config_from_mapping, placed_initial_state, tree_keys, tree_resolved
from ..config.paths import parse_any_key
from ..layout import LIMITED, STATE_SIZE, VARIANT_CODES, is_chain, joint_kind
from ..model import DISTURBANCE_KINDS, DISTURBANCE_QUANTITIES, PARAMETERS, SATURATION_SHAPES, set_limits
from ..variants import chain as C
from ..variants.registry import record_offsets
from .settings import SETTING_COLUMNS, SETTINGS, settings_records, settings_rows
from .tableaus import METHODS

__all__ = ["RunBatch", "batch_from_table", "batch_of", "TableFields", "tree_initial_states", "MAX_STATE", "NOT_COMPILED"]

#: The largest state of any variant (the second axis of a one-body table's :attr:`RunBatch.y0`).
MAX_STATE = max(STATE_SIZE)
#: ``RunBatch.settings["method"]`` of a run whose method is not one of
#: :data:`rbstab.engine.METHODS` (Radau, BDF, LSODA: integrated by scipy).
NOT_COMPILED = -1


class _Batch:
    """What a batch of runs of either model answers from its ``settings`` (n,)."""

    settings: np.ndarray

    def __len__(self) -> int:
        return len(self.settings)

    def settings_rows(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The settings of ``rows`` as floats, shape (k, 7): t_end, rtol, atol, max_step,
        gimbal_margin, max_steps, max_wall_time (what
        :func:`rbstab.engine.integrate_runs` takes)."""
        return settings_rows(self.settings[rows])


@dataclass(frozen=True)
class RunBatch(_Batch):
    """n runs as arrays (module docstring): every run a tree of 1-8 bodies (one body: its
    one-body tree, :attr:`rbstab.config.RunConfig.chain`). Every field has the run axis
    first.

    Attributes
    ----------
    trees : tuple of rbstab.variants.chain.CompiledChain
        The trees the runs are made of: their structure (laws, parents, embedded joints,
        names) is each run's; their records and points are a template's (each run's own
        are below).
    tree : ndarray of int64, shape (n,)
        Each run's tree, an index into ``trees``.
    params : ndarray of :data:`rbstab.model.PARAMETERS`, shape (n, B)
        Body i's record with joint i's gains and limits and the run's admissible region
        (``attachment_point``: joint i's R_c), as
        :func:`rbstab.variants.chain.compile_chain` makes it (SI units; body quantities in
        the body frame, gravity and the weight in the inertial frame); B the most bodies of
        any tree, a smaller tree's rows padded with zero records. A one-body run's record is
        :func:`rbstab.model.parameters`' with its ``lyapunov_offset``.
    ppoints : ndarray, shape (n, B, 3)
        Each joint's R_p [m].
    offset : ndarray, shape (n,)
        h [J] of each run (:func:`rbstab.variants.chain.rest_offset`).
    y0 : ndarray, shape (n, S)
        Initial states, zero-padded to the largest: a tree's in its maximal layout (12 n +
        3 e: Theta [rad], Omega [rad/s] (body frame), X [m], V [m/s] of every body, then
        each embedded joint's D [m]); a run of ``one_body`` in its variant's layout
        (:data:`rbstab.layout.VARIANT_LAYOUTS`: the same but for a permanent joint's 6
        states, Theta and Omega, the reduced state).
    n_state : ndarray of int64, shape (n,)
        The size of each run's ``y0``.
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
    one_body : ndarray of bool, shape (n,)
        Runs of configurations in the one-body spelling (``body`` and ``controller``):
        integrated by one body's compiled kernels, their results in one body's names and
        file format (:data:`rbstab.layout.OUTPUTS`).
    """

    trees: tuple
    tree: np.ndarray
    params: np.ndarray
    ppoints: np.ndarray
    offset: np.ndarray
    y0: np.ndarray
    n_state: np.ndarray
    settings: np.ndarray
    n_samples: np.ndarray
    compiled: np.ndarray
    one_body: np.ndarray

    def take(self, rows: np.ndarray) -> "RunBatch":
        """The runs ``rows`` (int indices, repeats allowed) as a batch of their own (copies)."""
        return dataclasses.replace(self, **{f.name: getattr(self, f.name)[rows] for f in dataclasses.fields(self)
                                            if f.name != "trees"})

    @property
    def codes(self) -> np.ndarray:
        """Each run's first joint's law (:data:`rbstab.layout.VARIANT_CODES`), shape (n,):
        a one-body run's variant."""
        return np.array([t.codes[0] for t in self.trees], dtype=np.int64)[self.tree]


class TableFields:
    """Each run's value of every numeric field of a table of runs (:func:`batch_from_table`'s
    arguments), as written (a 3-list stays shape (3,)): the templates' values with the
    varied keys' values set (a key of a list section's entry by its name or its position)."""

    def __init__(self, templates: Sequence[Mapping], keys: Sequence[str], columns: Mapping[str, np.ndarray],
                 template: np.ndarray) -> None:
        self.templates, self.template, self.n = templates, np.asarray(template), len(template)
        present = np.unique(self.template)
        # (template, its runs) of each template the runs use
        self.groups = [(int(t), np.flatnonzero(self.template == t)) if len(present) > 1 else (int(t), np.arange(self.n))
                       for t in present]
        self.varied: dict[tuple[str, str], list[tuple[tuple[int, ...], np.ndarray]]] = {}
        for key in keys:
            if columns[key].dtype == object:
                continue  # a template's own value (runs share a template's non-numeric values)
            path = parse_any_key(key)
            self.varied.setdefault((path.section, path.name), []).append((path.index, columns[key]))

    def get(self, section: str, name: str = "", default=None, *, shape: tuple | None = None,
            only: int | None = None) -> np.ndarray:
        """The field of every run (``name`` dotted inside a subsection or a list section's
        entry, ``bodies.trunk.mass``; "" the section itself, ``gravity``), shape (n,
        *shape): ``shape`` (3, 3) makes a matrix of a 3-list (its diagonal), as the
        configuration's loader does, (3,) 3 numbers of one and (2,) 2 (a universal joint's); ``default`` for a template
        without the field (None: a ValueError). ``only``: the runs of that template alone,
        shape (its runs, *shape)."""
        out = None
        groups = self.groups if only is None else [g for g in self.groups if g[0] == only]
        key = f"{section}.{name}" if name else section
        for t, rows in groups:
            written = parse_any_key(key).get(self.templates[t], None)
            aliases = [(section, name)]  # a list section's entry varied by its name or its position
            entry, _, rest = name.partition(".")
            listed = self.templates[t].get(section)
            if rest and isinstance(listed, list):
                at = next((k for k, e in enumerate(listed) if isinstance(e, Mapping) and e.get("name") == entry), None)
                if at is not None:
                    aliases.append((section, f"{at}.{rest}"))
            if written is None:
                if default is None:
                    raise ValueError(f"no {section}.{name} in template {int(t)}")
                written = default
            written_shape = shape if shape in ((3,), (2,)) else np.shape(written)
            value = np.broadcast_to(np.array(written, dtype=float), (len(rows), *written_shape)).copy()
            for index, column in (v for alias in aliases for v in self.varied.get(alias, ())):
                part = np.asarray(column[rows], dtype=float)
                if shape in ((3,), (2,)) and not index and part.ndim == 1:
                    part = np.broadcast_to(part[:, None], (len(rows), shape[0]))
                if index:
                    value[(slice(None), *index)] = part
                else:
                    value = part.copy()
            if shape == (3, 3) and value.ndim == 2:  # 3 numbers: a diagonal
                value = value[:, :, None] * np.eye(3)
            if out is None:
                out = np.empty((self.n if only is None else len(rows), *value.shape[1:]))
            out[rows if only is None else slice(None)] = value
        return np.zeros((0, *(shape or ()))) if out is None else out  # no runs

    def rows(self, t: int) -> np.ndarray:
        """The runs of template ``t``."""
        return next((rows for u, rows in self.groups if u == t), np.zeros(0, dtype=np.int64))

    def text(self, section: str, name: str) -> np.ndarray:
        """A template's text field (``controller.variant``, ``simulation.method``) of every run."""
        return self.of_templates([t[section][name] for t in self.templates], dtype=object)

    def of_templates(self, values: Sequence, dtype=None) -> np.ndarray:
        """Each run's entry of ``values`` (a value a template)."""
        return np.asarray(values, dtype=dtype)[self.template]


def _coordinates(values: np.ndarray, fill: float, diagonal: bool = False) -> np.ndarray:
    """A joint's numbers per coordinate ``values`` (k, 2) (a universal joint's; a slide's (k, 1)
    or (k,)) as its records' 3-vectors (k, 3), the rest ``fill``, or (``diagonal``) the
    diagonal matrices (k, 3, 3) of those."""
    values = np.asarray(values, dtype=float).reshape(len(values), -1)
    out = np.concatenate([values, np.full((len(values), 3 - values.shape[1]), fill)], axis=1)
    return out[:, :, None] * np.eye(3) if diagonal else out


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
    """The :class:`RunBatch` of n runs given as a table: one body's (templates in the
    one-body spelling) or trees' (``bodies`` and ``joints``; a table's templates are all one
    or all the other).

    Parameters
    ----------
    templates : sequence of mapping
        Validated resolved configurations (``RunConfig.resolved``;
        ``name`` ignored).
    keys : sequence of str
        Dotted config keys set on a run's template, in order (``body.mass``,
        ``controller.k_c.0``, ``initial_state.omega``, ``bodies.trunk.mass``,
        ``joints.hip.k_r.0`` ...); keys of
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
        One body's run i: ``params[i, 0]`` equals, bit for bit, :func:`rbstab.model.parameters`
        of its validated configuration with its ``lyapunov_offset``. A tree's run: its
        records are those of :func:`rbstab.variants.chain.compile_chain` for its validated
        configuration, its initial state placed as the configuration's loader places it
        (:func:`rbstab.config.loader.placed_initial_state`), h once per distinct tree.

    Raises
    ------
    ValueError
        If a key does not fit its template's value (a configuration the sweep's validation
        would have refused), or a template lacks a field.
    rbstab.config.ConfigError
        For a tree's template or run the sweep's validation would have refused.
    """
    one_body = not (len(templates) and is_chain(templates[0]))
    if one_body:  # its one-body tree's spelling (rbstab.config.RunConfig)
        templates = [tree_resolved(t) for t in templates]
        columns = {tree: columns[key] for key in keys for tree in tree_keys(key)}
        keys = [tree for key in keys for tree in tree_keys(key)]
    batch = _trees_from_table(templates, keys, columns, template, timeout=timeout, place=not one_body)
    return _paper_runs(batch) if one_body else batch


def _paper_runs(batch: RunBatch, rows: np.ndarray | None = None) -> RunBatch:
    """``batch`` with the one-body trees ``rows`` (bool (n,); None: every run) as the
    paper's one body runs them: each run's state its variant's
    (:data:`rbstab.layout.VARIANT_LAYOUTS`: a permanent joint's Theta and Omega), the
    states zero-padded to :data:`MAX_STATE` at least, and h in its record's
    ``lyapunov_offset`` (written in ``batch.params``)."""
    rows = np.ones(len(batch), dtype=bool) if rows is None else rows
    n_state = batch.n_state.copy()
    n_state[rows] = np.asarray(STATE_SIZE, dtype=np.int64)[batch.codes[rows]]
    y0 = np.zeros((len(batch), max(MAX_STATE, batch.y0.shape[1])))
    y0[:, : batch.y0.shape[1]] = batch.y0
    y0[np.arange(y0.shape[1]) >= n_state[:, None]] = 0.0
    batch.params["lyapunov_offset"][rows, 0] = batch.offset[rows]
    return dataclasses.replace(batch, y0=y0, n_state=n_state, one_body=rows.copy())


def _rigid(p: np.ndarray, mass: np.ndarray, inertia: np.ndarray, r: np.ndarray, gravity: np.ndarray) -> None:
    """The body's fields of the records ``p`` (k,) (:func:`rbstab.model.parameters`): m [kg],
    J and J^-1, R [m], J_p = J - m [R]x [R]x and J_p^-1, the weight m g [N], from each run's
    mass (k,), inertia (k, 3, 3), point R (k, 3) and gravity (k, 3)."""
    p["mass"], p["inertia"], p["attachment_point"] = mass, inertia, r
    p["inertia_inv"] = _inverse(inertia)
    r_hat = _hat(r)
    p["pivot_inertia"] = pivot = inertia - (mass[:, None, None] * r_hat) @ r_hat
    p["pivot_inertia_inv"] = _inverse(pivot)
    p["weight"] = mass[:, None] * gravity


def _settings(f: TableFields, templates: Sequence[Mapping], timeout: float | None) -> np.ndarray:
    """The runs' :data:`~rbstab.engine.settings.SETTINGS` (``timeout`` [s]: every run's
    ``max_wall_time``; the method's index, or :data:`NOT_COMPILED`)."""
    settings = np.zeros(f.n, dtype=SETTINGS)
    for name in SETTING_COLUMNS:
        value = f.get("simulation", name, np.inf) if name in ("max_step", "max_wall_time") else f.get("simulation", name)
        settings[name] = value
    if timeout is not None:
        settings["max_wall_time"] = float(timeout)
    settings["method"] = f.of_templates([_method(t["simulation"]["method"]) for t in templates])
    return settings


def _method(name: str) -> int:
    """A run's ``settings["method"]``: the index of ``name`` in :data:`METHODS`, else
    :data:`NOT_COMPILED` (an implicit method, integrated by scipy)."""
    return METHODS.index(name) if name in METHODS else NOT_COMPILED


def _disturbances(p: np.ndarray, f: TableFields, t: int, entries: Sequence[int]) -> None:
    """The disturbances' fields (:func:`rbstab.model.set_disturbances`) of the records ``p``
    of template ``t``'s runs: the ``entries`` of its ``disturbances`` list (positions), each
    number as written there or in a column (``disturbances.0.value.1``)."""
    listed = f.templates[t].get("disturbances") or ()
    p["disturbance_count"] = len(entries)
    for i, at in enumerate(entries):
        e = listed[at]
        p["disturbance_kind"][:, i] = DISTURBANCE_KINDS[e["kind"]]
        p["disturbance_torque"][:, i] = DISTURBANCE_QUANTITIES[e.get("quantity", "force")]
        value = f.get("disturbances", f"{at}.{'rms' if e['kind'] == 'noise' else 'value'}", [0.0, 0.0, 0.0],
                      shape=(3,), only=t)
        p["disturbance_value"][:, i] = value
        p["disturbance_point"][:, i] = f.get("disturbances", f"{at}.point", [0.0, 0.0, 0.0], shape=(3,), only=t)
        for field, default in (("start", 0.0), ("duration", 0.0), ("frequency", 0.0), ("phase", 0.0), ("seed", 0.0)):
            p[f"disturbance_{field}"][:, i] = f.get("disturbances", f"{at}.{field}", default, only=t)
        p["disturbance_band"][:, i] = f.get("disturbances", f"{at}.band", [0.0, 0.0], only=t)


def _bounds(f: TableFields, templates: Sequence[Mapping]) -> np.ndarray | None:
    """The admissible region of every run (:func:`rbstab.model.set_limits`), (n, 5, 3): each
    bound of its template's ``simulation.limits`` as written there or in a column
    (``simulation.limits.theta.1``), inf where absent; None where no run has one."""
    bounded = f.of_templates([bool(t["simulation"].get("limits")) for t in templates], dtype=bool)
    if not bounded.any():
        return None
    return np.stack([np.where(bounded[:, None], f.get("simulation", f"limits.{name}", math.inf, shape=(3,)), np.inf)
                     for name in LIMITED], axis=1)


# -- trees -----------------------------------------------------------------------------------------
def batch_of(configs: Sequence, timeout: float | None = None) -> RunBatch:
    """The :class:`RunBatch` of validated configurations (:class:`rbstab.config.RunConfig`
    in either spelling; ``timeout`` [s], if given, each run's ``max_wall_time``): each
    run's compiled tree's records (:func:`rbstab.variants.chain.compile_chain`, h included)
    with its admissible region, and its state; the runs in one body's spelling then in the
    paper's form (:func:`_paper_runs`), those of one law sharing one structure. Configs that
    share their Chain object share its compilation and h (a sweep over initial states
    compiles its chain once; :meth:`rbstab.config.RunConfig.from_resolved` with ``like``)."""
    n = len(configs)
    one_body = np.array([not is_chain(c) for c in configs], dtype=bool)  # the spelling, as a table's
    compiled: dict[int, tuple] = {}  # a chain's id -> (its compiled chain, the chain, kept alive)
    structures: dict = {}  # a tree's chain's id, or a one-body law's name -> its index in trees
    trees: list = []
    tree = np.empty(n, dtype=np.int64)
    for i, config in enumerate(configs):
        if id(config.chain) not in compiled:
            compiled[id(config.chain)] = (C.compile_chain(config.chain), config.chain)
        c = compiled[id(config.chain)][0]
        key = c.chain.joints[0].variant if one_body[i] else id(config.chain)
        if key not in structures:
            structures[key] = len(trees)
            trees.append(c)
        tree[i] = structures[key]
    width = max((c.size for c in trees), default=1)
    params, ppoints = np.zeros((n, width), dtype=PARAMETERS), np.zeros((n, width, 3))
    y0 = np.zeros((n, max((c.n_states for c in trees), default=0)))
    n_state, offset = np.zeros(n, dtype=np.int64), np.zeros(n)
    for i, config in enumerate(configs):
        c = compiled[id(config.chain)][0]
        params[i, : c.size], ppoints[i, : c.size], offset[i] = c.params, c.ppoints, c.offset
        set_limits(params[i, : c.size], config.simulation.limits)
        state = C.initial_state(config)
        y0[i, : len(state)], n_state[i] = state, len(state)
    settings = settings_records(settings_rows([c.simulation for c in configs], timeout), 0)
    settings["method"] = [_method(c.simulation.method) for c in configs]
    # the pure sign law (the paper's one body in either spelling: the loader refuses it in any other tree)
    sign_law = np.array([any(j.variant == "sliding" and not j.boundary_layer for j in c.chain.joints)
                         for c in configs], dtype=bool)
    batch = RunBatch(trees=tuple(trees), tree=tree, params=params, ppoints=ppoints, offset=offset, y0=y0,
                     n_state=n_state, settings=settings,
                     n_samples=np.array([c.simulation.n_samples for c in configs], dtype=np.int64),
                     compiled=(settings["method"] != NOT_COMPILED) & ~sign_law, one_body=np.zeros(n, dtype=bool))
    if not one_body.any():
        return batch
    batch = _paper_runs(batch, one_body)
    return dataclasses.replace(batch, y0=batch.y0[:, : max(int(batch.n_state.max()), 1)])


def _trees_from_table(templates: Sequence[Mapping], keys: Sequence[str], columns: Mapping[str, np.ndarray],
                      template: np.ndarray, *, timeout: float | None = None, place: bool = True) -> RunBatch:
    """:func:`batch_from_table` of trees' templates: each template validated once, every
    run's records built from the columns at once (``place``: :func:`tree_initial_states`')."""
    f = TableFields(templates, keys, columns, np.asarray(template, dtype=np.int64))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the sweep reported each template's warnings when it planned it
        configs = [config_from_mapping({**t, "name": "template"}) for t in templates]
    trees = tuple(C.compile_chain(c.chain, offset=0.0) for c in configs)
    n = f.n
    width = max((c.size for c in trees), default=1)
    params, ppoints = np.zeros((n, width), dtype=PARAMETERS), np.zeros((n, width, 3))
    y0, n_state = np.zeros((n, max((c.n_states for c in trees), default=0))), np.zeros(n, dtype=np.int64)
    offset = np.zeros(n)
    bounds = _bounds(f, templates)
    gravity = f.get("gravity", shape=(3,))
    for t, rows in f.groups:
        tree = trees[t]
        every = len(rows) == n  # one template: its records written in place (2 kB a record)
        records = params[:, : tree.size] if every else np.zeros((len(rows), tree.size), dtype=PARAMETERS)
        points = ppoints[:, : tree.size] if every else np.zeros((len(rows), tree.size, 3))
        for i in range(tree.size):
            _tree_record(records[:, i], f, t, tree.chain, i, gravity[rows])
            set_limits(records[:, i], None if bounds is None else bounds[rows])
            points[:, i] = f.get("joints", f"{tree.chain.joint_names[i]}.parent_point", shape=(3,), only=t)
        if not every:
            params[rows, : tree.size], ppoints[rows, : tree.size] = records, points
        n_state[rows] = tree.n_states
        y0[rows, : tree.n_states] = tree_initial_states(configs[t], tree, keys, columns, rows, records, points,
                                                        place=place)
        offset[rows] = _tree_offsets(tree, records, points, gravity[rows])
    settings = _settings(f, templates, timeout)
    sign_law = np.zeros(n, dtype=bool)  # a sliding joint without a boundary layer (only the paper's one body has one)
    for t, rows in f.groups:
        sliding = np.flatnonzero(trees[t].codes == VARIANT_CODES["sliding"])
        if len(sliding):
            sign_law[rows] = np.any(params["boundary_layer"][np.ix_(rows, sliding)] == 0, axis=1)
    return RunBatch(trees=trees, tree=f.template.copy(), params=params, ppoints=ppoints, offset=offset, y0=y0,
                    n_state=n_state, settings=settings, n_samples=f.get("simulation", "n_samples").astype(np.int64),
                    compiled=(settings["method"] != NOT_COMPILED) & ~sign_law, one_body=np.zeros(n, dtype=bool))


def _tree_record(p: np.ndarray, f: TableFields, t: int, chain, i: int, gravity: np.ndarray) -> None:
    """The records ``p`` of body i of template ``t``'s runs with its joint's gains and limits
    (:func:`rbstab.variants.chain.compile_chain`'s, ``chain`` the template's): each field as
    written there or in a column (``bodies.trunk.mass``, ``joints.hip.k_r.0``); a hinge's
    numbers about its axis as :func:`rbstab.chain.hinge_vectors` writes them."""
    body, joint = chain.bodies[i], chain.joints[i]

    def of(section: str, name: str, default=None, shape=None):
        owner = body.name if section == "bodies" else joint.name
        return f.get(section, f"{owner}.{name}", default, shape=shape, only=t)

    zero = [0.0, 0.0, 0.0]
    _rigid(p, of("bodies", "mass"), of("bodies", "inertia", shape=(3, 3)), of("joints", "child_point", shape=(3,)),
           gravity)
    for name in ("k_t", "l_t"):
        p[name] = of("bodies", name, zero, shape=(3, 3))
    hinged = joint.variant == "hinge"  # its gains, reference and limits numbers about its axis
    coordinates = {"universal": (2,), "slide": ()}.get(joint.variant)  # numbers per coordinate, entries of 3-vectors
    on_axes = joint_kind(joint.variant).axes > 0  # gains, reference and passive torque: numbers per coordinate
    for name in ("k_r", "l_r", "k_c", "l_c", "k_d", "l_d"):
        if not (on_axes and name in ("k_r", "l_r")):
            p[name] = of("joints", name, zero, shape=(3, 3))
    if joint.l_d is not None:
        p["l_d_inv"] = _inverse(p["l_d"])
    p["k_s"] = of("joints", "k_s", 0.0)
    p["boundary_layer"] = of("joints", "boundary_layer", 0.0)
    if not on_axes:
        p["theta_ref"] = of("joints", "theta_ref", zero, shape=(3,))
    if joint.passive is not None and not on_axes:
        p["passive"] = 1.0
        p["passive_k_r"] = of("joints", "passive.k_r", zero, shape=(3, 3))
        p["passive_l_r"] = of("joints", "passive.l_r", zero, shape=(3, 3))
        p["passive_theta_ref"] = of("joints", "passive.theta_ref", zero, shape=(3,))
    if hinged:
        upper = of("joints", "saturation.torque_n", math.inf) if joint.saturation else math.inf
        lower = of("joints", "saturation.torque_n_lower", math.nan) if joint.saturation else math.nan
        axis = of("joints", "axis", shape=(3,))
        p["axis"], p["k_r"], p["l_r"], p["theta_ref"], floor, limit = hinge_vectors(
            axis, of("joints", "k_r", 0.0), of("joints", "l_r", 0.0), of("joints", "theta_ref", 0.0),
            np.where(np.isnan(lower), -upper, lower), upper)
        if joint.passive is not None:
            p["passive"] = 1.0
            _, p["passive_k_r"], p["passive_l_r"], p["passive_theta_ref"], _, _ = hinge_vectors(
                axis, of("joints", "passive.k_r", 0.0), of("joints", "passive.l_r", 0.0),
                of("joints", "passive.theta_ref", 0.0))
    universal = coordinates is not None  # a universal joint's entries 0-1 of the records' 3-vectors, a slide's 0
    if universal:
        if joint.variant == "universal":
            p["axis"], p["axis_2"] = (a / np.linalg.norm(a, axis=-1, keepdims=True)
                                      for a in np.moveaxis(of("joints", "axis", shape=(2, 3)), 1, 0))
        else:
            axis = of("joints", "axis", shape=(3,))
            p["axis"] = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
        p["k_r"], p["l_r"] = (_coordinates(of("joints", name, 0.0, shape=coordinates), 0.0, True)
                              for name in ("k_r", "l_r"))
        p["theta_ref"] = _coordinates(of("joints", "theta_ref", 0.0, shape=coordinates), 0.0)
        upper = (of("joints", "saturation.torque_n", math.inf, shape=coordinates) if joint.saturation
                 else np.full((len(p), *coordinates), math.inf))
        lower = of("joints", "saturation.torque_n_lower", math.nan, shape=coordinates) if joint.saturation else np.nan
        limit, floor = _coordinates(upper, math.inf), _coordinates(np.where(np.isnan(lower), -upper, lower), -math.inf)
        if joint.passive is not None:
            p["passive"] = 1.0
            p["passive_k_r"], p["passive_l_r"] = (_coordinates(of("joints", f"passive.{name}", 0.0, shape=coordinates),
                                                               0.0, True) for name in ("k_r", "l_r"))
            p["passive_theta_ref"] = _coordinates(of("joints", "passive.theta_ref", 0.0, shape=coordinates), 0.0)
    if joint.stop is not None or joint.region is not None:  # a hinge's q (entry 0), a universal's q_1, q_2, a ball's
        p["stop" if joint.stop is not None else "region"] = 1.0
        for name, field in (("lower", "range_lower"), ("upper", "range_upper"), ("k_r", "stop_k"),
                            ("l_r", "stop_l"))[:4 if joint.stop is not None else 2]:
            default = 0.0 if name == "l_r" else None
            if joint.variant == "universal":
                p[field] = _coordinates(of("joints", f"range.{name}", default, shape=(2,)),
                                        {"lower": -math.inf, "upper": math.inf}.get(name, 0.0))
            else:
                p[field] = of("joints", f"range.{name}", default, shape=(3,))
    if joint.saturation is not None or body.saturation is not None:
        if hinged or universal:
            p["torque_limit"], p["torque_floor"] = limit, floor
        else:
            p["torque_limit"] = (of("joints", "saturation.torque_n", math.inf, shape=(3,)) if joint.saturation
                                 else math.inf)
            lower = of("joints", "saturation.torque_n_lower", math.nan, shape=(3,)) if joint.saturation else math.nan
            p["torque_floor"] = np.where(np.isnan(lower), -p["torque_limit"], lower)  # unwritten: -torque_n
        p["constraint_force_limit"] = (of("joints", "saturation.constraint_force", math.inf, shape=(3,))
                                       if joint.saturation else math.inf)
        p["force_limit"] = of("bodies", "saturation.force_h", math.inf, shape=(3,)) if body.saturation else math.inf
        p["saturation"] = SATURATION_SHAPES[(body.saturation or joint.saturation).shape]
    listed = f.templates[t].get("disturbances") or ()
    mine = [at for at, d in enumerate(listed) if d.get("body", body.name if chain.size == 1 else None) == body.name]
    if mine:
        _disturbances(p, f, t, mine)


def tree_initial_states(config, tree, keys: Sequence[str], columns: Mapping[str, np.ndarray], rows: np.ndarray,
                        params: np.ndarray, ppoints: np.ndarray, *, place: bool = True) -> np.ndarray:
    """The maximal initial states (k, n_states: Theta [rad], Omega [rad/s, body frame], X
    [m], V [m/s, inertial frame] of each body, then each embedded joint's D [m]) of the k
    runs ``rows`` of a table of one tree's runs as columns (``config``: their template's, validated; ``tree`` its compiled
    tree; ``params`` (k, n), ``ppoints`` (k, n, 3): the runs' records, or the template's
    (1, n), (1, n, 3) where no key moves a joint's point): the template's state with the
    runs' values of the varied ``initial_state.*`` keys (``keys``, their ``columns``) set,
    then the x and v the template leaves out and no key sets placed as the loader places
    them (:func:`rbstab.variants.chain.place`: on the parent's point, parents first), with
    each run's joint points (``place`` False: the template's x and v left as they are, for a
    state that leaves them out, the paper's pinned body's). The runs are validated: nothing is
    checked or raised here."""
    names = list(config.chain.body_names)
    varied = [k for k in keys if parse_any_key(k).section == "initial_state"]
    if varied and any(j.variant in ("hinge", "universal") for j in config.chain.joints):  # q turns what it carries
        return _hinged_initial_states(config, varied, columns, rows)
    y = np.repeat(C.state_vector(config.chain, config.initial_state)[None], len(rows), axis=0)
    placed = {"x": np.array([f"initial_state.{b}.x" in config.placed for b in names]),
              "v": np.array([f"initial_state.{b}.v" in config.placed for b in names])}
    moved = False  # whether the runs' joint points differ: each run is placed on its own
    for k in keys:
        path = parse_any_key(k)
        if path.section == "joints" and path.field in ("parent_point", "child_point"):
            moved = True
        if path.section != "initial_state":
            continue
        body, block = path.steps[1], path.steps[2]
        i = names.index(body)
        at = int(tree.d_at[i]) if block == "d" else 12 * i + 3 * ("theta", "omega", "x", "v").index(block)
        if block in placed and placed[block][i]:  # written by the runs: not placed, its entries not set zero
            placed[block][i] = False
            y[:, at: at + 3] = 0.0
        values = np.asarray(columns[k][rows], dtype=float)
        if len(path.steps) > 3:
            y[:, at + int(path.steps[3])] = values
        else:
            y[:, at: at + 3] = values.reshape(len(rows), 3)
    if not (place and (placed["x"].any() or placed["v"].any())):
        return y
    if not moved:
        return C.place(C.with_records(tree, params[0], ppoints[0]), y, placed["x"], placed["v"])
    return np.array([C.place(C.with_records(tree, params[a], ppoints[a]), y[a], placed["x"], placed["v"])
                     for a in range(len(rows))])


def _hinged_initial_states(config, keys: Sequence[str], columns: Mapping[str, np.ndarray],
                           rows: np.ndarray) -> np.ndarray:
    """:func:`tree_initial_states` of a tree with a hinge, whose angle turns every body it
    carries: each run's ``initial_state`` section (the template's with the run's values of the
    ``initial_state.*`` ``keys``) placed as the loader places it
    (:func:`rbstab.config.loader.placed_initial_state`), on the template's joints."""
    template = config.resolved["initial_state"]
    out = np.empty((len(rows), C.state_vector(config.chain, config.initial_state).size))
    for a, r in enumerate(rows):
        written = {body: {key: np.array(value, dtype=float) for key, value in state.items()}
                   for body, state in template.items()}
        for k in keys:
            steps = parse_any_key(k).steps
            value = written.setdefault(steps[1], {}).setdefault(steps[2], np.zeros(3))
            if len(steps) > 3:
                value[int(steps[3])] = columns[k][r]
            else:
                written[steps[1]][steps[2]] = np.asarray(columns[k][r], dtype=float)
        out[a] = C.state_vector(config.chain, placed_initial_state(written, config.chain,
                                                                   config.simulation.gimbal_margin))
    return out


def _tree_offsets(tree, params: np.ndarray, ppoints: np.ndarray, gravity: np.ndarray) -> np.ndarray:
    """h [J] of k runs of the tree ``tree`` (its structure) with the records ``params`` (k,
    n), parent points ``ppoints`` (k, n, 3) and gravity (k, 3):
    :func:`rbstab.variants.chain.rest_offset` once per distinct tree (0 without gravity and
    reference postures)."""
    out = np.zeros(len(params))
    posed = np.any(gravity != 0, axis=1) | np.any(params["theta_ref"] != 0, axis=(1, 2)) | np.any(
        params["passive_theta_ref"] != 0, axis=(1, 2))
    rows = np.flatnonzero(posed)
    if not len(rows):
        return out
    keys = np.array([params[a].tobytes() + ppoints[a].tobytes() + gravity[a].tobytes() for a in rows], dtype=object)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    if tree.one_body:  # the paper's one body: every distinct record's equilibrium at once
        found = record_offsets(params[rows[first], 0], gravity[rows[first]], tree.chain.joints[0].variant)
    else:
        found = np.array([C.rest_offset(C.with_records(tree, params[rows[a]], ppoints[rows[a]],
                                                       gravity=gravity[rows[a]])) for a in first])
    out[rows] = found[inverse.ravel()]
    return out
