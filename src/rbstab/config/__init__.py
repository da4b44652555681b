"""Run configuration: a YAML file -> a validated, frozen :class:`RunConfig`.

Validation happens here, once, at the boundary; the core (:mod:`rbstab.model`, the
variants, the integrator) trusts what it receives. Every problem in a configuration is
reported at once, one line each: the dotted key, the value found, what is allowed and,
in parentheses, what is wrong with it, e.g. (one line)::

    config key 'controller.k_t': found [1, 2]; expected 3 numbers (a diagonal) or a 3x3
    list of lists, symmetric positive definite (N/m) (2 entries, not 3)

Schema (the keys are public; units in brackets)::

    name: case3_embedded            # optional, default: the file stem; [A-Za-z0-9_.-]+
    body:
      mass: 41.0                    # m [kg] > 0, required
      inertia: [10.0, 8.0, 0.4]     # J [kg m^2]: 3 principal moments or a 3x3 list; SPD; required
      attachment_point: [0.15, 0.10, -0.42]  # R [m], body frame, required
      gravity: [0.0, 0.0, 0.0]      # g [m/s^2], inertial frame, default zeros
    controller:
      variant: embedded             # a key of rbstab.variants.VARIANTS, required
      k_t: [4100, 4100, 3280]       # gains k_t l_t k_r l_r k_c l_c k_d l_d: 3 numbers (a
      ...                           # diagonal) or a 3x3 list; symmetric positive
                                    # semi-definite (zeros allowed), l_d definite (it is
                                    # inverted, eq 22); required when the variant's
                                    # ``required_gains`` lists them
      k_s: 500.0                    # K_s [N] >= 0 (sliding, eq 39)
      boundary_layer: 0.0           # phi [m] >= 0, default 0 (pure sign function)
      saturation:                   # optional: what the actuators deliver (docs/saturation.md)
        torque_n: 120               # |N_i| <= limit [N m]: a number > 0 (.inf: none) or 3
        force_h: [800, 800, .inf]   # |H_i| <= limit [N]
        constraint_force: 2500      # |Lambda_i| <= limit [N] (not permanent, not the pure sign law)
        shape: clip                 # clip (default) | smooth (u_max tanh(u / u_max))
    initial_state:                  # each key 3 numbers, default zeros
      theta: [0, 0, 0]              # [rad], |theta_2| < pi/2 - gimbal_margin
      omega: [16, 32, -16]          # [rad/s], body frame
      x: [0, 0, 0]                  # [m]   -> state block 'position'
      v: [0, 0, 0]                  # [m/s] -> state block 'velocity'
      d: [0, 0, 0]                  # [m]   -> state block 'controller_state' (embedded)
    simulation:
      t_end: 2.0                    # [s] > 0
      n_samples: 2001               # integer >= 2
      method: DOP853                # a scipy solve_ivp method
      rtol: 1.0e-8                  # > 0
      atol: 1.0e-10                 # > 0
      max_step: .inf                # [s] > 0 (null means inf); t_end / max_step <= max_steps
      gimbal_margin: 1.0e-3         # [rad] in (0, 0.5)
      max_steps: 1000000            # solver steps after which the run fails, in [1, 1e9]
      max_wall_time: 600            # [s] of integration after which the run fails (null: none)
      limits:                       # optional: the admissible region (docs/physics.md); a run
        theta: [0.6, 0.6, 3.2]      # that leaves it fails there. |theta_i| <= bound [rad]: a
        omega: 20                   # number > 0 (every axis; .inf: none) or 3. |Omega_i| [rad/s],
        position: [1, 1, 1]         # |X_i| [m] (inertial frame, from the origin), |V_i| [m/s],
        velocity: 5                 # |E_i| [m] (not permanent); the initial state must lie
        constraint_error: 0.05      # inside
    disturbances:                   # optional, at most 4 (docs/disturbances.md)
      - kind: pulse                 # impulse | pulse | step | sine | noise
        quantity: force             # force (at point, inertial frame) | torque (body frame)
        value: [0, 40, 0]           # [N s] impulse; [N] amplitude (torque: N m s, N m)
        point: [0, 0, 0.2]          # [m], body frame, from the centre of mass (force only)
        start: 0.3                  # [s] in [0, t_end]
        duration: 0.05              # pulse; sine: frequency [Hz], phase [rad];
                                    # noise: rms, band [Hz], seed (instead of value)

Limits (docs/reliability.md): every number is at most 1e12 in magnitude; the mass and the
eigenvalues of the matrices the equations invert (inertia, l_d) are at least 1e-12;
``name`` has at most 200 characters; ``n_samples`` at most 1e7 (~1400 bytes each in
memory); samples are at least 1e-12 s apart. ``max_steps`` and ``max_wall_time`` bound
how long a run may take, not what it computes: they are not part of the run's
``config_hash`` (a run stopped by them is ``failed``; ``--retry-failed`` reruns it).

A tree of bodies (``bodies`` and ``joints`` instead of ``body`` and ``controller``) is
validated by the same loader into the same :class:`RunConfig` (:func:`load_config` and
:func:`config_from_mapping` take either spelling, :mod:`rbstab.config.loader`): its
``chain`` is the :class:`rbstab.chain.Chain` of any configuration, a one-body one being the
tree of one body held to the ground at its own point.

A run's identity is :func:`config_hash` of its :func:`canonical_config` (the resolved
configuration without ``name`` and the run limits, as canonical JSON;
:mod:`rbstab.config.identity`): result files store it, and ``rbstab run`` and ``rbstab
sweep`` do not run again a run whose stored result has it.

Gains the variant does not use (and ``initial_state.d`` for variants without a controller
state) are validated, kept in :attr:`RunConfig.resolved`, and otherwise ignored, so one
base configuration can serve a sweep over variants.

A singular (semi-definite or zero) gain the variant uses is valid physics, with a note
(:class:`SemiDefiniteGainWarning`): v is then not a strict Lyapunov function. With gravity,
gains that leave a direction in which nothing holds the weight (e.g. ``free`` with K_t
singular along g) are an error: there is no equilibrium (:mod:`rbstab.config.physics`).

YAML is read with a :class:`yaml.SafeLoader` subclass that differs in two ways: ``1e-8``
is a float (PyYAML follows YAML 1.1 and reads it as a string), and a key given twice in
one mapping is an error instead of silently keeping the last value.
"""

import importlib

from .errors import ConfigError, PhysicalPlausibilityWarning, SemiDefiniteGainWarning
from .identity import RUN_LIMIT_KEYS, canonical_config, canonical_configs, config_hash
from .yaml_io import dump_yaml, parse_yaml

# The validator (pydantic) and RunConfig (numba's model) are imported on first use, so that
# what only reads files (rbstab.open_sweep, rbstab show) does not load the compiler.
_LAZY = {
    "loader": ("PER_RUN_SECTIONS", "RunConfig", "config_from_mapping", "load_config"),
    "paths": ("apply_overrides", "parse_key", "KeyPath", "KeyPathError"),
    "schema": ("GAIN_NAMES", "GAIN_UNITS", "INITIAL_STATE_BLOCKS", "SimulationSettings"),
}


def __getattr__(name: str):
    for module, names in _LAZY.items():
        if name in names:
            value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
            globals()[name] = value  # once: `from .config import x` in a loop stays cheap
            return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "ConfigError",
    "PhysicalPlausibilityWarning",
    "SemiDefiniteGainWarning",
    "RunConfig",
    "SimulationSettings",
    "load_config",
    "config_from_mapping",
    "PER_RUN_SECTIONS",
    "apply_overrides",
    "parse_key",
    "KeyPath",
    "KeyPathError",
    "parse_yaml",
    "dump_yaml",
    "canonical_config",
    "canonical_configs",
    "config_hash",
    "RUN_LIMIT_KEYS",
    "GAIN_NAMES",
    "GAIN_UNITS",
    "INITIAL_STATE_BLOCKS",
]
