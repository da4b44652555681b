"""Imported by the sweep workers' fork server: load the compiled kernels once, before the
workers are forked from it (:func:`rbstab.sweep.executors._mp_context`).

Only from a warm cache: a cold one is compiled by the command before it starts workers
(:func:`rbstab.engine.ensure_compiled`); here a cold cache is left to the workers. Only the
engine's kernels: the sign law's (``switching``, ~0.1 s more on the way to the first run)
are loaded by a worker when a run needs them.
"""

from ..jit import cache_is_warm
from .warm import GROUPS, warm_up

if cache_is_warm("engine"):
    warm_up(",".join(GROUPS["engine"]))
