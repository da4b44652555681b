"""Errors and warnings of configuration loading."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["ConfigError", "PhysicalPlausibilityWarning", "SemiDefiniteGainWarning"]


class ConfigError(ValueError):
    """An invalid configuration, file or override.

    Attributes
    ----------
    errors : list of str
        One line per problem, e.g.
        ``config key 'body.mass': found -1; expected a number > 0 (kg)``.
    source : str or None
        The configuration file, if known; ``str()`` then starts with ``in <source>:``.
    """

    def __init__(self, errors: Sequence[str], source: str | None = None) -> None:
        super().__init__(list(errors), source)
        self.errors = list(errors)
        self.source = source

    def __str__(self) -> str:
        header = [f"in {self.source}:"] if self.source else []
        return "\n".join(header + self.errors)


class PhysicalPlausibilityWarning(UserWarning):
    """A configuration the equations accept but that deserves a note: no real rigid body
    has it (e.g. the inertia), or see the subclasses."""


class SemiDefiniteGainWarning(PhysicalPlausibilityWarning):
    """A gain that is positive semi-definite but singular (e.g. zero): valid physics (a
    torque-free body, a passive pendulum), but v is then not a strict Lyapunov function and
    asymptotic stability is not implied.

    A subclass of :class:`PhysicalPlausibilityWarning`, so whatever filters or collects
    those (the CLI, sweeps' digest) treats these notes alike.
    """
