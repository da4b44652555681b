"""Controller variants for the point C, one module each, and their registry.

``VARIANTS`` maps the config value ``controller.variant`` to the class implementing the
:class:`~rbstab.variants.base.Variant` protocol.
"""

from __future__ import annotations

from .base import LYAPUNOV_TERMS, Variant
from .embedded import Embedded
from .free import Free
from .permanent import Permanent
from .sliding import Sliding
from .visco_elastic import ViscoElastic

#: name -> variant class (the values allowed for ``controller.variant``).
VARIANTS: dict[str, type[Variant]] = {
    cls.name: cls for cls in (Free, Permanent, Sliding, ViscoElastic, Embedded)
}

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
