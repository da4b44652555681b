"""The paper's one-body variant (:class:`rbstab.variants.Variant`, in its own state) as an
independent reference: its run by ``solve_ivp`` alone (:func:`solve`, :func:`evaluate_outputs`),
its linearisation at its own equilibrium (:func:`linearise`) and its certificate model
(:class:`VariantModel`, a :class:`rbstab.analysis.certificate.Model`): the second formulation
the tree's runs and analysis (:func:`rbstab.analysis.linearise.linearise_chain`,
:class:`rbstab.analysis.certificate.ChainModel`) are compared with, and the model of the
linearisation's and certificate's closed-form checks."""

from __future__ import annotations

import numpy as np

from scipy.integrate import solve_ivp

from rbstab.analysis.certificate import coordinate_boundary_level
from rbstab.analysis.linearise import Linearisation, linearisation
from rbstab.summary import numerical_rate


def solve(variant, y0, settings):
    """The one-body variant's equations (``variant.rhs``) from ``y0`` integrated by
    ``solve_ivp`` alone (``settings``: t_end, n_samples, method, rtol, atol, max_step), without
    disturbances, admissible region or limits: (time (n_samples,), states (n_samples, n_state),
    NaN where the solver did not reach; status "success" or "failed", message, {"nfev"})."""
    time = np.linspace(0.0, settings.t_end, settings.n_samples)
    with np.errstate(all="ignore"):
        sol = solve_ivp(variant.rhs, (0.0, settings.t_end), np.asarray(y0, dtype=float), method=settings.method,
                        t_eval=time, rtol=settings.rtol, atol=settings.atol, max_step=settings.max_step)
    states = np.full((time.size, len(y0)), np.nan)
    solved = np.asarray(sol.y, dtype=float)
    if solved.ndim == 2:
        states[: solved.shape[1]] = solved.T
    return time, states, "success" if sol.status == 0 else "failed", str(sol.message), {"nfev": int(sol.nfev)}


def evaluate_outputs(variant, time, states) -> dict:
    """Every output of the variant along ``states`` (n, n_state) at ``time`` (n,)
    (:meth:`rbstab.variants.Variant.evaluate`) and the numerical dv/dt along the samples."""
    outputs = variant.evaluate(states, time)
    outputs["lyapunov_rate_numerical"] = numerical_rate(time, outputs["lyapunov"])
    return outputs


def linearise(variant) -> Linearisation:
    """Equilibrium (``variant.equilibrium``), rest check, Jacobian and eigenvalues of a
    one-body variant in its own state; ValueError for the pure sign law (no Jacobian at E = 0)."""
    if not variant.smooth:
        raise ValueError(f"{variant.name}: the right-hand side is not differentiable (the pure sign law, "
                         "boundary_layer 0): there is no linearisation")
    return linearisation(lambda y: variant.rhs(0.0, y), np.asarray(variant.equilibrium, dtype=float),
                         variant.body.gravity)


class VariantModel:
    """A one-body variant as a :class:`~rbstab.analysis.certificate.Model` in its own state:
    the domain |theta_2| < limit (eq 5, linear: ``y[1]``), the least v on its boundary
    minimised over the other configuration coordinates (Theta, X, D), runs from the state
    itself."""

    def __init__(self, variant) -> None:
        self.variant = variant
        self.angle_matrix = np.eye(variant.layout.size)[1:2]

    def lyapunov(self, x):
        return self.variant.lyapunov(x)

    def evaluate(self, x, t=0.0):
        return self.variant.evaluate(x, t)

    def rhs(self, t, x):
        return self.variant.rhs(t, x)

    def angles(self, x):
        return np.atleast_2d(x)[:, 1:2]

    def angle_jacobian(self, x):
        return self.angle_matrix

    def boundary_level(self, y_e, hess, limit):
        layout = self.variant.layout
        configuration = np.concatenate([np.arange(layout.slice(b).start, layout.slice(b).stop) for b in layout.blocks
                                        if b in ("theta", "position", "controller_state")])
        return coordinate_boundary_level(self.variant.lyapunov, y_e, hess, limit, [1], configuration)

    def states(self, x):
        return np.atleast_2d(x)
