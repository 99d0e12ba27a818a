"""``sensorimotor world``: make world files (generated floor plans, imported building maps).

Thin, as the rest of the command line: it parses, calls ``sim.floorplan`` or ``sim.rosmap``,
and writes the world file atomically; every user error is an InputError (one line, exit 2,
turned so by ``cli.main``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from sensorimotor.cli.app import app
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


def _check_toml(out: Path) -> None:
    if out.suffix.lower() != ".toml":
        raise InputError(f"{out}: --out must be a .toml file")
    check_writable(out)


@world_app.command("random")
def random_world(
    out: WorldOut,
    rooms: Annotated[int, typer.Option(help="Rooms of the plan.")] = 8,
    seed: Annotated[int, typer.Option(min=0, max=MAX_SEED, help="Seed of the plan.")] = 0,
    door: Annotated[float, typer.Option(help="Doorway width (units).")] = 1.5,
    size: Annotated[
        float | None, typer.Option(help="Side of the square world (default: 10 per room^0.5).")
    ] = None,
    name: Annotated[str | None, typer.Option(help="World name (default: planN-sS).")] = None,
) -> None:
    """A floor plan: a square split recursively into named rooms joined by doorways, every
    room reachable (checked by a flood fill)."""
    from sensorimotor.sim.floorplan import random_plan

    _check_toml(out)
    if size is not None and not 0 < size <= 10_000:
        raise InputError(f"--size must be positive and at most 10000, got {size}")
    world = random_plan(rooms, seed, door, None if size is None else (size, size), name=name)
    _write(world, out, f"sensorimotor world random --rooms {rooms} --seed {seed} --door {door:g}")


@world_app.command("import")
def import_world(
    map_yaml: Annotated[
        Path, typer.Argument(help="ROS map_server .yaml (beside its image) or MRPT .gridmap[.gz].")
    ],
    out: WorldOut,
    name: Annotated[str | None, typer.Option(help="World name (default: the map's).")] = None,
) -> None:
    """A building map: a ROS map_server occupancy grid (.yaml + .pgm/.png) or an MRPT
    occupancy grid (.gridmap, .gridmap.gz) as wall segments."""
    from sensorimotor.sim.rosmap import import_mrpt_map, import_ros_map

    _check_toml(out)
    mrpt = map_yaml.name.lower().endswith((".gridmap", ".gridmap.gz"))
    world, comment = (import_mrpt_map if mrpt else import_ros_map)(map_yaml, name)
    _write(world, out, comment)
