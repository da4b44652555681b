"""What a machine offers a run: available memory, and whether a run fits in it.

The limits a configuration must respect wherever it runs are validated with it
(:mod:`rbstab.config.schema`: ``n_samples`` at most ``MAX_SAMPLES``); this module checks
the machine at hand before work starts, so that a run too large for it is refused with
its estimate instead of failing (or swapping) midway.
"""

from __future__ import annotations

import os

__all__ = ["available_memory", "memory_problem", "LARGE_RUN_BYTES"]

#: A run holding more than this is announced with its estimate before it starts.
LARGE_RUN_BYTES = 2**30


def available_memory() -> int | None:
    """Memory [bytes] this machine can give a new allocation now (Linux ``MemAvailable``,
    else the free physical pages), or None where unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return None


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.3g} GiB"


def memory_problem(n_samples: int, name: str = "the run") -> tuple[str | None, str | None]:
    """(refusal, note) for a run of ``n_samples`` samples on this machine.

    ``refusal`` when its memory estimate (:func:`rbstab.config.schema.run_memory_estimate`)
    exceeds the available memory; ``note`` when it is large (> :data:`LARGE_RUN_BYTES`)
    but fits. Both None for an ordinary run.
    """
    from .config.schema import BYTES_PER_SAMPLE, run_memory_estimate  # heavy: numba, numpy, pydantic, yaml

    need = run_memory_estimate(n_samples)
    if need <= LARGE_RUN_BYTES:
        return None, None
    have = available_memory()
    what = f"{name}: {n_samples} samples hold ~{_gib(need)} in memory (~{BYTES_PER_SAMPLE} bytes per sample)"
    if have is not None and need > have:
        return f"{what}, more than the {_gib(have)} available; lower simulation.n_samples", None
    return None, what
