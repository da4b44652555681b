"""``rbstab validate``: check configs and sweep specs without running them."""

from __future__ import annotations

import click

from rbstab.layout import is_chain, joint_kind

from ._common import (config_error_text, load_one, show_config_warnings, stiffness_warnings,
                      template_stiffness_warnings)
from .console import get_console
from .options import console_options, json_option, set_option


def _is_spec(path: str) -> bool:
    from rbstab.config import ConfigError  # heavy: numpy, pydantic
    from rbstab.config.yaml_io import read_yaml_file  # heavy: numpy, pydantic

    try:
        data = read_yaml_file(path, "file")
    except ConfigError:
        return False  # reported by the config loader
    return isinstance(data, dict) and "base" in data


def _check_spec(path: str, overrides) -> dict:
    """One JSON-able record of a sweep spec: valid or not, its runs, its warnings."""
    from rbstab.sweep import SweepSpecError, load_spec, plan_table  # heavy: numpy, pydantic

    try:
        loaded = load_spec(path, overrides)
        table = plan_table(loaded)
    except SweepSpecError as exc:
        return {"path": path, "kind": "sweep", "valid": False, "errors": list(exc.errors)}
    return {"path": path, "kind": "sweep", "valid": True, "name": loaded.name, "n_runs": table.n,
            "warnings": [*table.warnings, *template_stiffness_warnings(loaded, table)]}


def _check_config(path: str, overrides) -> dict:
    """One JSON-able record of a run config: valid or not, its settings, its warnings, its
    tree's bodies and joints (a one-body config's: its body held by its controller) and for
    a one-body config its variant."""

    config, error, lines = load_one(path, overrides)
    if config is None:
        return {"path": path, "kind": "config", "valid": False, "errors": list(error.errors),
                "text": config_error_text(path, error)}
    sim = config.simulation
    record = {"path": path, "kind": "config", "valid": True, "name": config.name}
    if not is_chain(config):
        record["variant"] = config.chain.joints[0].variant
    record["chain"] = _chain_record(config.chain)
    lines = [*lines, *stiffness_warnings([config]).get(config.name, [])]
    return record | {"t_end": sim.t_end, "n_samples": sim.n_samples, "method": sim.method, "warnings": lines}


def _listed(end, variant: str):
    """A range's end as JSON: a hinge's number, a universal joint's 2, a ball's 3 [rad]."""
    if not hasattr(end, "tolist"):
        return float(end)
    return end.tolist()[:2] if variant == "universal" else end.tolist()


def _chain_record(chain) -> dict:
    """A chain's bodies and joints, JSON-able, parents by name (``ground``: the inertial frame); a
    hinge's unit axis, its reference angle q_ref [rad] and its range's ends [rad]."""
    from rbstab.chain import GROUND  # heavy: numpy

    names = chain.body_names
    return {
        "bodies": [{"name": b.name, "mass": b.mass} for b in chain.bodies],
        "joints": [{"name": j.name, "parent": "ground" if j.parent == GROUND else names[j.parent],
                    "child": names[j.child], "variant": j.variant, "parent_point": j.parent_point.tolist(),
                    "child_point": j.child_point.tolist(),
                    **({"axis": j.axis.tolist(), "theta_ref": float(j.axis @ j.theta_ref)} if j.variant == "hinge"
                       else {"axis": j.axis.tolist(), "theta_ref": float(j.theta_ref[0])} if j.variant == "slide"
                       else {"axis": [j.axis.tolist(), j.axis_2.tolist()], "theta_ref": j.theta_ref[:2].tolist()}
                       if j.variant == "universal" else {"theta_ref": j.theta_ref.tolist()}),
                    **({"range": [_listed(end, j.variant) for end in (j.stop.lower, j.stop.upper)]}
                       if j.stop is not None else {}),
                    "passive": j.passive is not None} for j in chain.joints],
    }


def _tree(chain: dict) -> list[str]:
    """The chain as an indented tree, one line a joint: parent -> child (its mass): the
    joint's name, variant (a hinge's or a slide's with its axis) and points (the parent's, the
    child's C) [m], its reference posture [rad; a slide's m] where it has one, whether it has a
    passive torque (force) and a hinge's range [rad; a slide's m]."""
    mass = {b["name"]: b["mass"] for b in chain["bodies"]}
    children: dict[str, list[dict]] = {}
    for joint in chain["joints"]:
        children.setdefault(joint["parent"], []).append(joint)

    def point(values) -> str:
        return "[" + ", ".join(f"{v:g}" for v in values) + "]"

    lines: list[str] = []

    def walk(parent: str, depth: int) -> None:
        for j in children.get(parent, ()):
            reference = j.get("theta_ref")
            if isinstance(reference, (int, float)):  # a hinge's angle
                reference = f"{reference:g}" if reference else None
            elif reference is not None:
                reference = point(reference) if any(reference) else None
            unit = joint_kind(j["variant"]).unit
            span = j.get("range")
            span = None if span is None else f"[{span[0]:g}, {span[1]:g}]" if isinstance(span[0], (int, float)) else \
                f"[{point(span[0])}, {point(span[1])}]"
            kind = (f"hinge about {point(j['axis'])}" if j["variant"] == "hinge" else
                    f"slide along {point(j['axis'])}" if j["variant"] == "slide" else
                    f"universal about {point(j['axis'][0])}, then {point(j['axis'][1])}" if j["variant"] == "universal"
                    else j["variant"])
            lines.append(f"{'  ' * depth}{parent} -> {j['child']} ({mass[j['child']]:g} kg): {j['name']}, "
                         f"{kind}, {point(j['parent_point'])} -> {point(j['child_point'])} m"
                         + (f", theta_ref {reference} {unit}" if reference else "")
                         + (f", passive {'force' if unit == 'm' else 'torque'}" if j.get("passive") else "")
                         + (f", range {span} {unit} (a stop)" if span else ""))
            walk(j["child"], depth + 1)

    walk("ground", 1)
    return lines


def _say(record: dict) -> None:
    console = get_console()
    if not record["valid"]:
        return
    if record["kind"] == "sweep":
        console.out(f"ok: sweep {record['name']} ({record['n_runs']} runs)")
        for line in record["warnings"]:
            console.warn(line, record["name"])
        return
    n = len(record["chain"]["bodies"])
    what = record.get("variant") or f"chain of {n} bod{'y' if n == 1 else 'ies'}"
    console.out(f"ok: {record['name']} ({what}, t_end {record['t_end']:g} s, {record['n_samples']} samples, "
                f"{record['method']})")
    for line in _tree(record["chain"]):
        console.out(line)


@click.command("validate")
@click.argument("configs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@set_option
@json_option
@console_options
def validate(configs, overrides, as_json) -> None:
    """Validate CONFIG... and sweep specs (with --set overrides applied); exit non-zero if any is invalid.

    A sweep spec (a file with a ``base`` key) is expanded: every run's config is validated.
    Every config is shown as its tree of bodies: one line a joint, parent -> child (mass),
    the joint's name, variant and points (a one-body config: ground -> body, its
    controller, at its attachment point).
    With --json: one object per file, with "path", "kind" (config or sweep), "valid" and
    either "errors" or "name", the settings ("chain" with its "bodies" and "joints"; a
    one-body config's "variant") and "warnings".
    """
    console = get_console()
    records = [_check_spec(p, overrides) if _is_spec(p) else _check_config(p, overrides) for p in configs]
    configs_found = {r["name"]: r["warnings"] for r in records if r["kind"] == "config" and r["valid"]}
    show_config_warnings(configs_found, sum(r["kind"] == "config" for r in records))
    for record in records:
        _say(record)
        if console.json:
            console.emit({k: v for k, v in record.items() if k != "text"})
    bad_configs = [r["text"] for r in records if not r["valid"] and r["kind"] == "config"]
    problems = (["invalid configuration", *bad_configs] if bad_configs else []) + [
        f"invalid sweep spec {r['path']}\n" + "\n".join("  " + e for e in r["errors"])
        for r in records if not r["valid"] and r["kind"] == "sweep"]
    if problems:
        raise click.ClickException("\n".join(problems))
