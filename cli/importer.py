"""``rbstab import``: an MJCF or URDF model -> a commented config that runs as written."""

from __future__ import annotations

from pathlib import Path

import click

from .console import get_console
from .options import console_options


@click.command("import")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Write the config to this YAML file (default: stdout).")
@click.option("--keyframe", default=None, metavar="NAME",
              help="The model's keyframe that gives the initial state and the servos' controls "
                   "(default: the reference pose at rest, zero controls).")
@click.option("--overwrite", is_flag=True, help="Replace the -o file if it exists.")
@console_options
def import_(model, output, keyframe, overwrite) -> None:
    """Write the rbstab config of MODEL, an MJCF (.xml) or URDF (.urdf) file, read through
    MuJoCo's compiler (the ``mujoco`` package: pip install 'rbstab[import]').

    \b
    rbstab import configs/examples/models/stance.xml --keyframe lean -o stance.yaml
    rbstab run stance.yaml

    Bodies (mass, inertia tensor, centre of mass), hinge joints (anchors, axes; a body's two
    hinges through one point as a universal joint), slide joints (URDF prismatic), ball joints
    (free of gimbal lock), their springs and dampers (stiffness, damping, springref), position
    servos on hinges and slides (kp, kv, forcerange, gear), ranges (as stops; a ball's as a
    cone), gravity and the initial state (a keyframe or the reference pose), in the model's
    world frame; each value commented with its units and its source. A gain the model lacks is
    written as 0 and named in a note (stderr). What rbstab cannot represent (free joints,
    actuators on balls,
    tendons, equality constraints, muscles) is refused in one line naming the element;
    nothing is written then. docs/import.md.
    """
    from rbstab.config import ConfigError, config_from_mapping  # heavy: numpy, pydantic
    from rbstab.config.model_import import import_model  # heavy: numpy, and MuJoCo when called
    from rbstab.config.yaml_io import parse_yaml  # heavy: yaml
    from rbstab.io.atomic import write_text_atomic  # heavy: hashlib, socket

    console = get_console()
    if output is not None and Path(output).exists() and not overwrite:
        raise click.ClickException(f"{output} exists; choose another -o or pass --overwrite to replace it")
    try:
        imported = import_model(model, keyframe=keyframe)
    except ConfigError as exc:
        raise click.ClickException("\n".join(exc.errors)) from None
    config_from_mapping(parse_yaml(imported.text))  # it loads as written, or a bug raises here
    for note in imported.notes:
        console.info(f"note: {note}")
    if output is None:
        click.echo(imported.text, nl=False)
        return
    write_text_atomic(output, imported.text)
    console.info(f"{imported.name}: {model} -> {output}")
