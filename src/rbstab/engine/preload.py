"""Imported by the sweep workers' fork server: load the compiled kernels once, before the
workers are forked from it (:func:`rbstab.sweep.executors._mp_context`).

Only from a warm cache: a cold one is compiled by the command before it starts workers
(:func:`rbstab.jit.ensure_compiled`); here a cold cache is left to the workers.
"""

from ..jit import GROUPS, cache_is_warm

_warm = [part for group, parts in GROUPS.items() if cache_is_warm(group) for part in parts]
if _warm:
    from . import warm_up

    warm_up(",".join(_warm))
