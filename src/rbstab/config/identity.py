"""A run's identity: its resolved configuration as canonical JSON, and the hash of it.

Two configurations that compute the same run have the same :func:`config_hash` of their
:func:`canonical_config`: the text leaves out ``name`` and the run limits
(:data:`RUN_LIMIT_KEYS`), and sorts keys, so it does not depend on YAML formatting. A run
file's and a store file's ``config_hash`` attribute, a sweep's run ids
(``r<index>-<config_hash[:8]>``) and the resume of ``rbstab run`` and ``rbstab sweep``
(a stored result whose hash is the run's is not run again) all use it.
"""

from __future__ import annotations

import functools
import hashlib
import json

__all__ = ["RUN_LIMIT_KEYS", "SECTION_MEMO", "canonical_config", "canonical_configs", "config_hash"]


#: ``simulation`` keys that bound how long a run may take, not what it computes: not part
#: of its identity (:func:`canonical_config`), so changing them reruns nothing (a run they
#: stopped is ``failed``: ``rbstab sweep --retry-failed`` reruns it).
RUN_LIMIT_KEYS = ("max_steps", "max_wall_time")


def canonical_config(resolved, *, limits: bool = False) -> str:
    """A resolved configuration without its ``name`` as canonical JSON (sorted keys, no
    spaces), and without the run limits (:data:`RUN_LIMIT_KEYS`) unless ``limits``.

    ``json.loads`` reads it back; :func:`config_hash` of the text without the limits is the
    run's identity (a store file's ``config`` column holds the text with them).
    """
    body = {k: v for k, v in resolved.items() if k != "name"}
    sim = body.get("simulation")
    if not limits and isinstance(sim, dict) and any(k in sim for k in RUN_LIMIT_KEYS):
        body["simulation"] = {k: v for k, v in sim.items() if k not in RUN_LIMIT_KEYS}
    return _canonical_json(body)


#: The encoder of :func:`canonical_config` (one instance: ``json.dumps`` with arguments builds
#: an encoder a call).
_CANONICAL = json.JSONEncoder(sort_keys=True, separators=(",", ":"), allow_nan=True)
_canonical_json = _CANONICAL.encode


def canonical_configs(resolved, memo: dict | None = None) -> tuple[str, str]:
    """``(canonical_config(resolved), canonical_config(resolved, limits=True))``: the same
    texts, for about the cost of one. A sweep's plan takes both (the run's hash and the text
    its store file holds), so a worker does not encode the config again.

    ``memo``: a dict a caller keeps while it encodes many configs that share section
    objects which no one changes (a sweep's plan: the runs of a base share its ``body``,
    ``controller`` and ``simulation`` where they are not varied): a section met again (the
    same object) is not encoded again; it holds the :data:`SECTION_MEMO` sections met
    most recently.
    Without it, the text with the limits is encoded once and its ``simulation`` section
    (the last, keys being sorted) replaced by its encoding without them.
    """
    sim = resolved.get("simulation")
    limited = isinstance(sim, dict) and any(k in sim for k in RUN_LIMIT_KEYS)
    keys = sorted(k for k in resolved if k != "name") if all(type(k) is str for k in resolved) else None
    if memo is None or keys is None:
        full = canonical_config(resolved, limits=True)
        if not limited:
            return full, full
        tail = '"simulation":' + _canonical_json(sim) + "}"
        if not full.endswith(tail):
            return canonical_config(resolved), full
        short = _canonical_json({k: v for k, v in sim.items() if k not in RUN_LIMIT_KEYS})
        return full[: -len(tail)] + '"simulation":' + short + "}", full
    # "{key:value,...}" in sorted key order, as json.dumps(sort_keys=True) joins them
    parts = [f"{_key_json(k)}:{_section_json(resolved[k], memo)}" for k in keys]
    full = "{" + ",".join(parts) + "}"
    if not limited:
        return full, full
    parts[keys.index("simulation")] = '"simulation":' + _section_json(sim, memo, short=True)
    return "{" + ",".join(parts) + "}", full


#: A key's JSON (a config has a few keys, met again in every run).
_key_json = functools.lru_cache(maxsize=256)(_canonical_json)

#: Sections a :func:`canonical_configs` memo holds (the least recently met is dropped).
SECTION_MEMO = 32


def _section_json(value, memo: dict, short: bool = False) -> str:
    """A section's canonical JSON (``short``: a ``simulation`` section without its run
    limits), from ``memo`` when the same object was encoded before."""
    key = (id(value), short)
    hit = memo.get(key)
    if hit is not None and hit[0] is value:
        memo[key] = memo.pop(key)  # the newest again: the shared sections stay, each run's own go
        return hit[1]
    if short:
        text = _canonical_json({k: v for k, v in value.items() if k not in RUN_LIMIT_KEYS})
    else:
        text = _canonical_json(value)
    if isinstance(value, (dict, list)):  # containers only: the memo holds the object, so its id stays its own
        if len(memo) >= SECTION_MEMO:
            del memo[next(iter(memo))]
        memo[key] = (value, text)
    return text


def config_hash(text: str) -> str:
    """SHA-256 hex digest of ``text``; a run's ``config_hash`` is that of its
    :func:`canonical_config` (so it does not depend on its name or on YAML formatting,
    and the run id of a sweep run is ``r<index>-<config_hash[:8]>``)."""
    return hashlib.sha256(text.encode()).hexdigest()
