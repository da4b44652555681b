"""Controller variants for the point C, one module each, and their registry.

``VARIANTS`` maps the config value ``controller.variant`` to the class implementing the
:class:`~rbstab.variants.base.Variant` protocol.
"""

from __future__ import annotations

from .base import LYAPUNOV_TERMS, Variant
from .registry import VARIANTS, Embedded, Free, Permanent, Sliding, ViscoElastic

__all__ = [
    "VARIANTS",
    "Variant",
    "Free",
    "Permanent",
    "Sliding",
    "ViscoElastic",
    "Embedded",
    "LYAPUNOV_TERMS",
]
