"""Imported by the sweep workers' fork server, last: load the compiled kernels once, before
the workers are forked from it (:func:`rbstab.sweep.executors._mp_context`), then freeze
the objects alive (:func:`gc.freeze`).

Only from a warm cache: a cold one is compiled by the command before it starts workers
(:func:`rbstab.engine.ensure_compiled`); here a cold cache is left to the workers. Only the
engine's kernels: the sign law's (``switching``, ~0.1 s more on the way to the first run)
are loaded by a worker when a run needs them.
"""

import gc

from ..jit import cache_is_warm
from .warm import GROUPS, warm_up

if cache_is_warm("engine"):
    warm_up(",".join(GROUPS["engine"]))

# The last module the fork server imports: the objects alive now (numpy's, numba's, the
# kernels') are frozen, as the standard library advises before forking (gc.freeze). The
# cyclic collections of the workers forked from here, and those of the fork server's own
# exit, skip them: its exit takes ~0.05 s instead of ~0.45-0.65 s, and a sweep ends when
# it has exited (it holds the command's stdout and stderr).
gc.freeze()
