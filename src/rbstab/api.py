"""rbstab from Python (a notebook, a script): the functions the command line is built on.

::

    import rbstab

    config = rbstab.load_config("configs/paper/case3_embedded.yaml", overrides={"name": "case3_short",
                                                                                "simulation.t_end": 1.0})
    ds = rbstab.simulate(config)               # xarray.Dataset: a result file's content, in memory
    ds.lyapunov.plot(yscale="log")             # v [J] against time [s]
    path = rbstab.run(config, "results")       # results/case3_short.h5 (rbstab run)
    ds = rbstab.open_result(path)              # the same Dataset, read back and verified
    sw = rbstab.sweep_dataset("configs/sweeps/gains.yaml", grid=True)   # rbstab sweep, then open_sweep
    rbstab.write_report([path], "results/reports/case3")                # rbstab report

Every function validates its input first and raises one exception naming what is wrong:
:class:`rbstab.config.ConfigError` (a config key, the value found, what is allowed),
:class:`rbstab.sweep.SweepSpecError`, :class:`ResultExistsError`, ... A run that fails
(gimbal lock, solver failure, a step or time limit) is data, not an exception: its
Dataset's ``status`` attribute is ``"failed"`` with the reason in ``message``.

Result datasets
---------------
Dimensions ``time`` (coordinate, s) and ``axis`` (``x``, ``y``, ``z``). Variables, each
with ``units`` and ``description``: the state ``theta`` [rad] (Euler angles, A = Rx Ry Rz,
eq 2), ``omega`` [rad/s] (body frame), ``position`` [m] and ``velocity`` [m/s] (inertial
frame), ``controller_state`` [m] (embedded); ``constraint_error`` E [m] and
``constraint_rate`` F [m/s], ``constraint_force`` Lambda [N], ``force_h`` H [N],
``torque_n`` N [N m]; ``lyapunov`` v [J] with its terms ``lyapunov_translational``,
``lyapunov_rotational``, ``lyapunov_constraint``, ``lyapunov_gravity``, its analytic
rate ``lyapunov_rate`` [W] and ``lyapunov_rate_numerical`` [W]. Vectors have dims
``(time, axis)``, scalars ``(time,)``. Global attributes: the resolved ``config`` (YAML),
``config_hash``, ``status``, ``message``, provenance, solver statistics and the
``summary_*`` figures (:mod:`rbstab.io.hdf5`).
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from .engine.registry import DEFAULT_ENGINE

if TYPE_CHECKING:  # pragma: no cover
    import xarray

    from .config import RunConfig
    from .results import RunResult
    from .sweep import SweepOutcome, SweepSpec

__all__ = [
    "load_config",
    "simulate",
    "run",
    "check_overwrite",
    "open_result",
    "sweep_dataset",
    "execute_sweep",
    "write_report",
    "ResultExistsError",
]

Overrides = Sequence[str] | Mapping[str, Any]


class ResultExistsError(FileExistsError):
    """A result file of another configuration is in the way (:func:`run` without ``overwrite``).

    Attributes
    ----------
    path : Path
        The existing file.
    differences : list of str
        ``key: stored -> new`` for the first config keys that differ (empty when the file
        cannot be read as a result).
    """

    def __init__(self, message: str, path: Path, differences: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.path = path
        self.differences = list(differences)

    def __str__(self) -> str:
        return self.args[0]


# -- configurations -----------------------------------------------------------------------------


def _override_lines(overrides: Overrides) -> list[str]:
    """``key.path=value`` lines: strings as given, a mapping's values written as YAML."""
    if isinstance(overrides, str):
        return [overrides]
    if isinstance(overrides, Mapping):
        from .config import dump_yaml  # heavy: yaml
        from .config.paths import plain_tree  # heavy: numba, numpy, pydantic, yaml

        return [f"{key}={dump_yaml(plain_tree(value)).strip()}" for key, value in overrides.items()]
    return list(overrides)


def load_config(source: str | os.PathLike | Mapping | "RunConfig", overrides: Overrides = (),
                *, name: str | None = None) -> "RunConfig":
    """Read, override and validate a run configuration: one body's, or a tree's.

    Parameters
    ----------
    source : path-like, Mapping, RunConfig
        A YAML file (its stem is the default ``name``), a mapping of the same shape (the
        parsed YAML, see the README's "Configuration" and "Chains of bodies"), or a
        validated configuration (its ``resolved`` mapping, validated again with the
        overrides).
    overrides : sequence of str or Mapping
        ``["simulation.t_end=1.5", "initial_state.omega.0=5"]`` (values parsed as YAML, as
        ``rbstab run --set``) or ``{"simulation.t_end": 1.5, "controller.k_t": [1, 2, 3]}``.
    name : str, optional
        The name of a mapping that has none (default ``"run"``); a file's default name is
        its stem.

    Returns
    -------
    RunConfig
        Frozen and validated. One body's: ``body`` (mass [kg], inertia [kg m^2] 3x3,
        attachment point R [m] body frame, gravity g [m/s^2] inertial frame), ``gains``
        (3x3), ``initial_state``, ``simulation``, ``resolved`` (every default filled in),
        ``warnings`` (coded lines, :mod:`rbstab.warning_codes`). A tree's: ``chain`` (its
        bodies, joints and gravity, :class:`rbstab.chain.Chain`), ``initial_state`` by body,
        ``simulation``, ``resolved``, ``warnings``.

    Raises
    ------
    rbstab.config.ConfigError
        Listing every problem: the dotted key, the value found and what is allowed.

    Warns
    -----
    rbstab.config.PhysicalPlausibilityWarning
        ``W001``/``W002`` (an inertia no real body has, a singular gain).
    """
    from .config import RunConfig, config_from_mapping  # heavy: yaml
    from .config import load_config as load_file  # heavy: yaml

    lines = _override_lines(overrides)
    if isinstance(source, RunConfig):
        source = source.resolved
    if isinstance(source, Mapping):
        data = dict(source)
        if name is not None and "name" not in data:
            data["name"] = name
        return config_from_mapping(data, default_name="run", source="<mapping>", overrides=lines)
    if not isinstance(source, (str, os.PathLike)):
        from .config import ConfigError  # heavy: yaml

        raise ConfigError([f"load_config: found {type(source).__name__}; expected a path, a mapping or a "
                           "RunConfig"])
    return load_file(source, lines)


def _config(config: Any, overrides: Overrides) -> "RunConfig":
    """A validated config of ``config`` (a path or a validated config) with ``overrides``."""
    from .config import RunConfig  # heavy: yaml

    if isinstance(config, RunConfig) and not overrides:
        return config
    return load_config(config, overrides)


# -- one run ------------------------------------------------------------------------------------


def _integrate(config, engine: str, timeout: float | None) -> "RunResult":
    """The run (one body or a tree), the compiled kernels its model needs made first (once
    per machine and version, cached: :func:`rbstab.engine.ensure_compiled`)."""
    from .engine import ensure_compiled, kernel_groups  # heavy: numba, numpy
    from .simulator import simulate as integrate  # heavy: numba, numpy

    ensure_compiled(sign_law=config.chain.sign_law, **kernel_groups([config], engine))
    return integrate(config, timeout, engine=engine)


def simulate(config: Any, overrides: Overrides = (), *, engine: str = DEFAULT_ENGINE,
             timeout: float | None = None) -> "xarray.Dataset":
    """Integrate one run and return what its result file would hold, in memory.

    Parameters
    ----------
    config : RunConfig, path-like or Mapping
        A validated config (one body or a chain), or what :func:`load_config` takes (a
        chain's file too).
    overrides : sequence of str or Mapping
        See :func:`load_config`.
    engine : {"compiled", "scipy", "cuda"}
        :data:`rbstab.engine.ENGINES`; Radau, BDF and LSODA always go through scipy.
    timeout : float, optional
        Wall-time limit of the integration [s], instead of ``simulation.max_wall_time``.

    Returns
    -------
    xarray.Dataset
        The variables, units and attributes of a result file (the module docstring;
        :func:`rbstab.io.hdf5.result_dataset`), ``time`` of length
        ``simulation.n_samples``. A failed run has ``attrs["status"] == "failed"``, the
        reason in ``attrs["message"]`` and NaN after the failure.

    Raises
    ------
    rbstab.config.ConfigError
        For an invalid configuration or override.
    ValueError
        For an unknown engine.

    Notes
    -----
    The first run on a machine compiles the kernels its model needs (the paper's one
    body's ~1 min on 2 cores, a tree's ~2 min), cached for every later run and process
    (:mod:`rbstab.jit`).
    """
    from .io.hdf5 import result_dataset  # heavy: numpy

    config = _config(config, overrides)
    result = _integrate(config, engine, timeout)
    return result_dataset(result, command_line=_python_command("simulate"))


def _python_command(function: str) -> str:
    """The ``command_line`` attribute of a result made from Python."""
    return f"rbstab.{function}() in {' '.join(sys.argv) or 'python'}"


def _differences(stored: Mapping | list, new: Mapping | list, prefix: str = "", limit: int = 3) -> list[str]:
    """``key: stored -> new`` for the first ``limit`` leaves that differ (``name`` aside);
    lists of one length are compared item by item (``initial_state.omega.0: 16.0 -> 5``)."""
    out: list[str] = []
    if isinstance(stored, list):
        stored, new = dict(enumerate(stored)), dict(enumerate(new))
    for key in dict.fromkeys([*stored, *new]):
        if not prefix and key == "name":
            continue
        a, b = stored.get(key), new.get(key)
        nested = isinstance(a, Mapping) and isinstance(b, Mapping)
        if nested or (isinstance(a, list) and isinstance(b, list) and len(a) == len(b)):
            out += _differences(a, b, f"{prefix}{key}.", limit - len(out))
        elif a != b:
            out.append(f"{prefix}{key}: {a!r} -> {b!r}")
        if len(out) >= limit:
            break
    return out[:limit]


def _stored_config(path: Path) -> tuple[str | None, dict | None]:
    """(config_hash, resolved config) of an existing result file; (None, None) if unreadable."""
    from .config import parse_yaml  # heavy: yaml
    from .io.hdf5 import read_attributes  # heavy: numpy

    try:
        attrs = read_attributes(path)
        stored = parse_yaml(attrs.get("config", "")) if attrs.get("config") else None
    except (OSError, ValueError):  # not a result, damaged, unreadable (ConfigError is a ValueError)
        return None, None
    return attrs.get("config_hash"), stored if isinstance(stored, dict) else None


def check_overwrite(config: "RunConfig", path: str | os.PathLike, *, overwrite: bool = False
                    ) -> Literal["new", "identical", "replace"]:
    """Whether :func:`run` may write ``config``'s result to ``path``.

    Returns
    -------
    str
        ``"new"`` (no file there), ``"identical"`` (a result of the same resolved config:
        the same ``config_hash``, which leaves out ``name`` and the run limits
        ``max_steps``, ``max_wall_time``; it is replaced) or ``"replace"`` (another file,
        replaced because ``overwrite``).

    Raises
    ------
    ResultExistsError
        If a file of another configuration (or not a readable result) is there and not
        ``overwrite``: the message names the keys that differ.
    """
    from .config import canonical_config, config_hash  # heavy: numba, numpy, pydantic, yaml

    path = Path(path)
    if not path.exists():
        return "new"
    stored_hash, stored = _stored_config(path)
    if stored_hash == config_hash(canonical_config(config.resolved)):
        return "identical"
    if overwrite:
        return "replace"
    differences = _differences(stored, config.resolved) if stored is not None else []
    what = (f"a result of a different configuration ({'; '.join(differences)})" if differences else
            "a result of a different configuration" if stored_hash else "a file that is not a readable rbstab result")
    raise ResultExistsError(f"{path} holds {what}: not replaced; --overwrite (overwrite=True) replaces it, "
                            "-o DIR writes elsewhere", path, differences)


def run(config: Any, output: str | os.PathLike = "results", *, overrides: Overrides = (), overwrite: bool = False,
        engine: str = DEFAULT_ENGINE, timeout: float | None = None, command_line: str | None = None) -> Path:
    """Integrate one run and write ``<output>/<name>.h5`` (what ``rbstab run`` does).

    Parameters
    ----------
    config, overrides, engine, timeout
        See :func:`simulate`.
    output : path-like
        Folder of the result file (created if missing).
    overwrite : bool
        Replace a result of another configuration. Without it such a file is refused
        before anything runs; a result of the identical configuration is replaced.
    command_line : str, optional
        Recorded in the file's ``command_line`` attribute.

    Returns
    -------
    Path
        The file, written atomically (complete or absent); read it with :func:`open_result`.
        A failed run is written too, with ``status`` ``"failed"``.

    Raises
    ------
    rbstab.config.ConfigError
        For an invalid configuration.
    ResultExistsError
        See :func:`check_overwrite`.
    OSError
        If the file cannot be written (a full disk, a read-only folder).
    """
    from .io.hdf5 import write_result  # heavy: numpy

    config = _config(config, overrides)
    path = Path(output) / f"{config.name}.h5"
    check_overwrite(config, path, overwrite=overwrite)
    result = _integrate(config, engine, timeout)
    return write_result(result, path, command_line=command_line or _python_command("run"))


def open_result(path: str | os.PathLike) -> "xarray.Dataset":
    """Read a result file (``rbstab run``, :func:`run`) into memory, checksums verified.

    Returns
    -------
    xarray.Dataset
        As :func:`simulate` returns it (the module docstring); the file is closed.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    rbstab.io.hdf5.NotAResultFile
        If it is not an rbstab run result (a sweep's store file: open its folder with
        :func:`open_sweep`).
    rbstab.io.integrity.DamagedResultError
        If its checksums do not match (a subclass of NotAResultFile).
    """
    from .kinds import CHAIN_RUN, RUN, open_input  # heavy: numba, numpy, pydantic, yaml

    return open_input(path, (RUN, CHAIN_RUN))  # another kind is refused, saying what it is and how to read it


# -- sweeps -------------------------------------------------------------------------------------


def _load_spec(spec: Any, overrides: Overrides) -> "SweepSpec":
    from .sweep import SweepSpec, load_spec, spec_from_mapping  # heavy: pydantic (the spec's schema)

    lines = _override_lines(overrides)
    if isinstance(spec, SweepSpec):
        if lines:
            raise ValueError("overrides: give them with the spec's file or mapping, not with a loaded SweepSpec")
        return spec
    if isinstance(spec, Mapping):
        return spec_from_mapping(spec, overrides=lines)
    return load_spec(spec, lines)


def _sweep_executor(executor: Any, scheduler: str | None, connect_timeout: float | None):
    """(executor or its name, owned): a Dask executor is connected here, before anything is
    compiled, so that an unreachable scheduler is reported within ``connect_timeout``."""
    if executor is None:
        executor = "dask" if scheduler else "local"
    if executor == "dask":
        if not scheduler:
            raise ValueError("executor 'dask' needs scheduler='tcp://HOST:PORT'")
        from .sweep.executors import DASK_CONNECT_TIMEOUT, make_executor  # heavy: multiprocessing

        timeout = DASK_CONNECT_TIMEOUT if connect_timeout is None else connect_timeout
        return make_executor("dask", scheduler=scheduler, connect_timeout=timeout), True
    if scheduler:
        raise ValueError(f"scheduler: found {scheduler!r} with executor {executor!r}; a scheduler is for 'dask'")
    if connect_timeout is not None:
        raise ValueError("connect_timeout: only for executor 'dask' (the time to reach its scheduler)")
    return executor, False


def execute_sweep(spec: Any, output: str | os.PathLike = "results/sweeps", *, overrides: Overrides = (),
                  executor: Any = None, jobs: int | None = None, scheduler: str | None = None,
                  connect_timeout: float | None = None, log=None, **options) -> "SweepOutcome":
    """Run a sweep (``rbstab sweep``) and return its :class:`rbstab.sweep.SweepOutcome`.

    Parameters
    ----------
    spec : path-like, Mapping or SweepSpec
        A sweep spec file (or a run config, varied through ``sweep.*`` overrides), its
        mapping, or a loaded spec (:func:`rbstab.sweep.load_spec`).
    output : path-like
        Parent folder: the sweep writes ``<output>/<name>/``.
    overrides : sequence of str or Mapping
        As for :func:`load_config`, applied to every base; ``sweep.*`` keys change the spec.
    executor : {"local", "dask"} or rbstab.sweep.Executor, optional
        Default ``"dask"`` with a ``scheduler``, else ``"local"``. An Executor passed in
        is not closed (several sweeps can share its started workers).
    jobs : int, optional
        Local processes (default: all CPUs).
    scheduler : str, optional
        Dask scheduler address ``tcp://HOST:PORT`` (implies ``executor="dask"``).
    connect_timeout : float, optional
        Seconds to wait for the Dask scheduler (default
        :data:`rbstab.sweep.executors.DASK_CONNECT_TIMEOUT`, 5).
    log : callable, optional
        Receives one-line status messages.
    **options
        ``timeout``, ``retry_failed``, ``engine``, ``chunk_size``, ``store``, ``layout``,
        ``progress``, ``command_line`` of :func:`rbstab.sweep.run_sweep`.

    Raises
    ------
    rbstab.sweep.SweepSpecError
        For an invalid spec or run (every problem listed; nothing is run or written).
    rbstab.sweep.ExecutorError
        If ``distributed`` is missing or no Dask scheduler answers at ``scheduler``
        within ``connect_timeout`` (the message names the address).
    rbstab.sweep.SweepBusyError
        If another process is writing the same sweep folder.
    ValueError
        For options that do not fit together (a scheduler with ``executor="local"``).
    """
    from .engine import ensure_compiled  # heavy: numba, numpy
    from .sweep import run_sweep  # heavy: numpy, h5py (the sweep's runner and its files)

    loaded = _load_spec(spec, overrides)
    ex, owned = _sweep_executor(executor, scheduler, connect_timeout)
    try:
        one_body = loaded.may_run_one_body  # compiled once, before any worker starts
        ensure_compiled(say=log, one_body=one_body, sign_law=one_body, chain=loaded.may_run_tree,
                        solve_ivp=loaded.may_run_scipy(options.get("engine")))
        return run_sweep(loaded, output, executor=ex, jobs=jobs, log=log, **options)
    finally:
        if owned:
            ex.close()


def sweep_dataset(spec: Any, output: str | os.PathLike = "results/sweeps", *, grid: bool = False,
                  **options) -> "xarray.Dataset":
    """Run a sweep and open it: :func:`execute_sweep`, then :func:`open_sweep`.

    Parameters
    ----------
    spec, output, **options
        See :func:`execute_sweep` (``overrides``, ``jobs``, ``executor``, ``scheduler``,
        ``connect_timeout``, ``store``, ...).
    grid : bool
        Reshape the ``run`` dimension to the sweep's axes (:func:`open_sweep`).

    Returns
    -------
    xarray.Dataset
        Every run along ``run`` (or the grid's axes) with the varied parameters as
        coordinates, the summary figures and ``status``; ``attrs["folder"]`` is the sweep
        folder. Failed runs are data (``status``), not exceptions.

    Raises
    ------
    See :func:`execute_sweep`.
    """
    from .sweep.folder import open_sweep  # heavy: numpy

    outcome = execute_sweep(spec, output, **options)
    return open_sweep(outcome.directory, grid=grid)


# -- reports ------------------------------------------------------------------------------------


def write_report(inputs: str | os.PathLike | Sequence[str | os.PathLike], output: str | os.PathLike | None = None,
                 *, overwrite: bool = False, **options) -> Path:
    """Build a report folder (``rbstab report``): tables, figures, the comparison with the paper.

    Parameters
    ----------
    inputs : path-like or sequence of path-like
        Run files (``*.h5``), sweep folders, folders of run files, analysis files
        (``*.analysis.nc``), in any mix.
    output : path-like, optional
        The report folder (default under ``results/reports/``); an earlier report there
        of the same inputs (in any order) is rebuilt, one of other inputs (an input more or
        fewer, another run of the same name) only with ``overwrite=True``, any other
        non-empty folder refused.
    overwrite : bool
        Replace an earlier report of other inputs.
    **options
        Fields of :class:`rbstab.report.ReportOptions` (``formats``, ``metrics``,
        ``settle``, ``title``, ``figure_formats``, ``dpi``, ``animation_frames``, ``jobs``).
        With ``jobs`` > 1 (or None: one per CPU) the figures are drawn in that many
        processes, and a script that calls this needs ``if __name__ == "__main__":``, as
        for :func:`sweep_dataset` (without it: ``ExecutorError`` before anything is
        written); the default ``jobs=1`` draws them in this process.

    Returns
    -------
    Path
        The report folder (``index.html``, ``summary.md``, ``summary.csv``, ``figures/``).

    Raises
    ------
    rbstab.report.ReportInputError
        If an input is missing or not an rbstab result (every problem listed).
    rbstab.report.ReportError
        For an invalid option or an output folder that cannot be used.
    TypeError
        For an unknown option (the message lists the known ones).
    """
    from .report import ReportOptions, build_report  # heavy: numpy

    known = [f.name for f in dataclasses.fields(ReportOptions)]
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise TypeError(f"write_report: unknown option {', '.join(unknown)}; expected some of {', '.join(known)}")
    if options.get("jobs", 1) != 1:
        from .sweep.executors import refuse_at_script_top_level  # heavy: multiprocessing

        refuse_at_script_top_level("a report")  # before the folder is touched
    paths = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    return build_report(paths, output, ReportOptions(**options), overwrite=overwrite)
