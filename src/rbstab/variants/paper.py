"""The paper's one-body form of a run: the tree of one body held to the ground at its own point.

A tree of one body whose joint holds the body's point C (``child_point`` R, body frame) to
the same point of the ground (``parent_point`` = R, inertial frame) is the paper's model
(eqs 1-24): one body with the constraint error E = X + A R - R (eq 4), zero at the
equilibrium X = 0, Theta = 0, held by its joint's law (the variant) with the joint's K_r,
L_r and point gains and the body's ground-anchored K_t, L_t. :func:`paper_form` gives that
model as the :class:`~rbstab.variants.base.Variant` of its law, whatever the spelling of
its configuration (``body``/``controller`` or ``bodies``/``joints``): the analyses that
hold for the paper's equations (the linearisation, the certificate, ``--verify``, the
sign law) take it from here. Any other tree has no paper form (None).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..chain import GROUND, Chain
from ..model import Gains, Limits, RigidBody, Saturation
from .base import Variant
from .registry import VARIANTS

__all__ = ["paper_form", "has_paper_form", "paper_initial_state", "body_model"]


def has_paper_form(chain: Chain) -> bool:
    """Whether ``chain`` is one body held to the ground at its own point (R_p = R_c) by one of
    the paper's five laws (not a hinge or a universal joint) with the paper's feedback (its spring relaxed at Theta = 0, no passive torque, symmetric torque
    limits)."""
    if chain.size != 1:
        return False
    joint = chain.joints[0]
    lower = None if joint.saturation is None else joint.saturation.torque_n_lower
    return (joint.variant in VARIANTS and joint.parent == GROUND and np.array_equal(joint.parent_point, joint.child_point)
            and not np.any(joint.theta_ref) and joint.passive is None
            and (lower is None or np.array_equal(lower, -np.asarray(joint.saturation.torque_n))))


def body_model(chain: Chain, i: int) -> tuple[RigidBody, Gains]:
    """Body ``i`` of ``chain`` with its joint, as the paper writes one body: the body (Table 1:
    mass [kg], inertia [kg m^2] about the centre of mass, body frame; its joint's point R_c
    [m], body frame, as the attachment point; gravity [m/s^2], inertial frame) and the gains
    of eqs 22-24 (the joint's K_r, L_r, point gains, K_s and boundary layer, the body's K_t,
    L_t), the limits of N and Lambda (the joint's) and of H (the body's; the body's shape
    where both have limits), the body's disturbances. A chain's record of body i and its
    joint is :func:`rbstab.model.parameters` of these (:mod:`rbstab.variants.chain`)."""
    body, joint = chain.bodies[i], chain.joints[i]
    limits = [np.full(3, np.inf)] * 3
    shape, lower = "clip", None
    if joint.saturation is not None:
        limits[0], limits[2], shape = joint.saturation.torque_n, joint.saturation.constraint_force, joint.saturation.shape
        lower = joint.saturation.torque_n_lower
    if body.saturation is not None:
        limits[1], shape = body.saturation.force_h, body.saturation.shape
    limited = joint.saturation is not None or body.saturation is not None
    gains = Gains(k_t=body.k_t, l_t=body.l_t, k_r=joint.k_r, l_r=joint.l_r, k_c=joint.k_c, l_c=joint.l_c,
                  k_d=joint.k_d, l_d=joint.l_d, k_s=joint.k_s, boundary_layer=joint.boundary_layer,
                  saturation=Saturation(*limits, shape, lower) if limited else None, disturbances=body.disturbances)
    rigid = RigidBody(mass=body.mass, inertia=np.asarray(body.inertia, dtype=float),
                      attachment_point=np.asarray(joint.child_point, dtype=float),
                      gravity=np.asarray(chain.gravity, dtype=float))
    return rigid, gains


def paper_form(config: Any, *, saturation: bool = True, disturbances: bool = True) -> Variant | None:
    """The paper's one-body model of a validated run configuration, or None.

    Parameters
    ----------
    config : rbstab.config.RunConfig
        Its ``chain`` and ``simulation.limits`` are read.
    saturation : bool
        False: the model without its actuators' limits (the paper's linear feedback).
    disturbances : bool
        False: the model without its disturbances.

    Returns
    -------
    Variant or None
        ``VARIANTS[law](body, gains, simulation.limits)`` of :func:`body_model` of the one
        body: the same record as the chain's. None where the chain is not one body held to
        the ground at its own point (:func:`has_paper_form`).
    """
    chain = config.chain
    if not has_paper_form(chain):
        return None
    rigid, gains = body_model(chain, 0)
    if not saturation or not disturbances:
        gains = dataclasses.replace(gains, saturation=gains.saturation if saturation else None,
                                    disturbances=gains.disturbances if disturbances else ())
    limits: Limits | None = config.simulation.limits
    return VARIANTS[chain.joints[0].variant](rigid, gains, limits)


def paper_initial_state(config: Any, variant: Variant | None = None) -> np.ndarray:
    """The paper form's initial state (its layout's size,) of ``config``: its one body's
    blocks (``variant``: its :func:`paper_form`, made if not given)."""
    variant = paper_form(config) if variant is None else variant
    return variant.initial_state(config.initial_state[config.chain.bodies[0].name])
