"""``sensorimotor world``: make world files (generated floor plans, imported building maps).

Thin, as the rest of the command line: it parses, calls ``sim.floorplan`` or ``sim.rosmap``,
and writes the world file atomically; every user error is an InputError (one line, exit 2,
turned so by ``cli.main``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from sensorimotor.cli.app import (
    MAX_CLEARANCE,
    MAX_DOOR,
    MAX_ROOMS,
    MAX_SCALE,
    MAX_SIZE,
    app,
    writes,
)
from sensorimotor.errors import InputError
from sensorimotor.files import check_writable, write_text_atomic
from sensorimotor.sim import MAX_SEED

world_app = typer.Typer(
    help="Make world files: generated floor plans, imported ROS or MRPT building maps.",
    no_args_is_help=True,
)
app.add_typer(world_app, name="world")
WorldOut = Annotated[Path, typer.Option(help="Output .toml world file (written atomically).")]


def _write(world, out: Path, comment: str) -> None:
    from sensorimotor.sim.floorplan import world_toml

    write_text_atomic(out, world_toml(world, comment))
    rooms = f", {len(world.rooms)} rooms" if world.rooms else ""
    typer.echo(
        f"wrote {out} ({world.name}: {world.width:g} x {world.height:g}, "
        f"{len(world.walls):,} inner walls{rooms})",
        err=True,
    )


def _check_name(name: str | None) -> None:
    from sensorimotor.sim.world import BUILTIN_WORLDS

    if name is not None and name.lower() in BUILTIN_WORLDS:
        raise InputError(
            f"--name {name}: the name of a built-in world ({', '.join(BUILTIN_WORLDS)}); "
            "choose another (the commands would take the built-in one)"
        )


def _check_toml(out: Path) -> None:
    if out.suffix.lower() != ".toml":
        raise InputError(f"{out}: --out must be a .toml file")
    check_writable(out)


@world_app.command("random")
@writes(files=("out",))
def random_world(
    out: WorldOut,
    rooms: Annotated[
        int,
        typer.Option(
            min=1,
            max=MAX_ROOMS,
            help="Rooms of the plan (the work grows as rooms^2 x size^2: 40 rooms of the "
            "default size take about 5 s).",
        ),
    ] = 8,
    seed: Annotated[int, typer.Option(min=0, max=MAX_SEED, help="Seed of the plan.")] = 0,
    door: Annotated[float, typer.Option(min=0, max=MAX_DOOR, help="Doorway width (units).")] = 1.5,
    size: Annotated[
        float | None,
        typer.Option(
            min=0, max=MAX_SIZE, help="Side of the square world (default: 10 per room^0.5)."
        ),
    ] = None,
    name: Annotated[str | None, typer.Option(help="World name (default: planN-sS).")] = None,
) -> None:
    """A floor plan: a square split recursively into named rooms joined by doorways, every
    room reachable (checked by a flood fill)."""
    from sensorimotor.sim.floorplan import check_plan_work, random_plan

    _check_name(name)
    _check_toml(out)
    if size is not None and not 0 < size <= MAX_SIZE:
        raise InputError(f"--size must be positive and at most {MAX_SIZE:g}, got {size}")
    check_plan_work(rooms, size)
    world = random_plan(rooms, seed, door, None if size is None else (size, size), name=name)
    _write(world, out, f"sensorimotor world random --rooms {rooms} --seed {seed} --door {door:g}")


@world_app.command("import")
@writes(files=("out",))
def import_world(
    map_yaml: Annotated[
        Path, typer.Argument(help="ROS map_server .yaml (beside its image) or MRPT .gridmap[.gz].")
    ],
    out: WorldOut,
    name: Annotated[str | None, typer.Option(help="World name (default: the map's).")] = None,
    clearance: Annotated[
        float | None,
        typer.Option(
            min=0,
            max=MAX_CLEARANCE,
            help="Free places narrower than this (units) are closed before the walls are drawn, "
            "so the paper's behaviour cannot enter a pocket it cannot turn out of; 0 keeps every "
            "free cell. Default: 2 (twice the turn-around distance) for an MRPT grid, 0 for a "
            "ROS map (its doorways are narrower).",
        ),
    ] = None,
    scale: Annotated[
        float,
        typer.Option(
            min=0,
            max=MAX_SCALE,
            help="World units a metre of the map (1: a unit is a metre; the paper's robot sees "
            "10 units and steps at most 1).",
        ),
    ] = 1.0,
) -> None:
    """A building map: a ROS map_server occupancy grid (.yaml + .pgm/.png) or an MRPT
    occupancy grid (.gridmap, .gridmap.gz) as wall segments."""
    from sensorimotor.sim.rosmap import import_mrpt_map, import_ros_map, units

    _check_name(name)
    _check_toml(out)
    mrpt = map_yaml.name.lower().endswith((".gridmap", ".gridmap.gz"))
    importer = import_mrpt_map if mrpt else import_ros_map
    more = {} if clearance is None else {"clearance": clearance}
    world, comment = importer(map_yaml, name, scale=scale, **more)
    _write(world, out, comment)
    typer.echo(f"units: {units(scale)}", err=True)
