"""Commands of the simulator layer: databases (generate, import-bag, import-rawlog) and the paper's
figures of the simulator (plot)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from sensorimotor.cli.app import (
    DATABASE,
    MAX_FOV,
    MAX_MOTOR_NOISE,
    MAX_NOISE,
    MAX_RANGE,
    MAX_RATE,
    MAX_SCALE,
    MAX_STEPS,
    MAX_VIEW,
    PlotOut,
    PlotSvg,
    WorldArg,
    app,
    err_console,
    plot_app,
    progress,
    reads,
    writes,
)
from sensorimotor.errors import InputError
from sensorimotor.sim import MAX_RAYS, MAX_SEED


def default_name(world: str, seed: int, rays: int, fov: float, range_: float, noise: float,
                 noise_kind: str, dropout: float, motor_noise: float,
                 behaviour: str = "paper") -> Path:  # fmt: skip
    """``WORLD_sSEED.npz`` with each setting that differs from the paper's recording appended,
    so that two different recordings never take one default name."""
    parts = [f"{world}_s{seed}"]
    parts += [f"rays{rays}"] if rays != 5 else []
    parts += [f"fov{fov:g}"] if fov != 1.2 else []
    parts += [f"range{range_:g}"] if range_ != 10.0 else []
    parts += [f"noise{noise:g}" + ("rel" if noise_kind == "relative" else "")] if noise else []
    parts += [f"dropout{dropout:g}"] if dropout else []
    parts += [f"motornoise{motor_noise:g}"] if motor_noise else []
    parts += [behaviour] if behaviour != "paper" else []
    return Path("_".join(parts) + ".npz")


@app.command()
@writes(files=("out",))
def generate(
    world: WorldArg,
    steps: Annotated[
        int, typer.Option(min=1, max=MAX_STEPS, help="Number of steps (rows) to record.")
    ] = 1_000_000,
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed of the random generator (PCG64).")
    ] = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output .npz (default: WORLD_sSEED.npz, with what differs from the paper's "
            "recording appended, e.g. rooms1_s0_rays64_noise0.05.npz)."
        ),
    ] = None,
    rays: Annotated[
        int, typer.Option(min=1, max=MAX_RAYS, help="Lasers recorded; the paper's: 5.")
    ] = 5,
    fov: Annotated[
        float,
        typer.Option(
            min=0,
            max=MAX_FOV,
            help="Field of view (rad, up to 2 pi: a full turn), centred on the heading.",
        ),
    ] = 1.2,
    range_: Annotated[
        float,
        typer.Option(
            "--range",
            min=0,
            max=MAX_RANGE,
            help="What a laser reads when no wall is nearer (units).",
        ),
    ] = 10.0,
    noise: Annotated[
        float,
        typer.Option(
            min=0, max=MAX_NOISE, help="Std of Gaussian noise on each reading (see --noise-kind)."
        ),
    ] = 0.0,
    noise_kind: Annotated[
        str,
        typer.Option(help="absolute: --noise in units; relative: a fraction of the reading."),
    ] = "absolute",
    dropout: Annotated[
        float,
        typer.Option(min=0, max=1, help="Probability that a reading drops out (reads the range)."),
    ] = 0.0,
    motor_noise: Annotated[
        float,
        typer.Option(
            min=0,
            max=MAX_MOTOR_NOISE,
            help="Std of Gaussian noise on the executed d and r (the chosen are kept).",
        ),
    ] = 0.0,
    behaviour: Annotated[
        str,
        typer.Option(
            help="paper: the paper's random walk (a new turn each step); smooth: a turning "
            "rate that drifts (Ornstein-Uhlenbeck); lattice: forward 0.9 or a turn of pi/6, "
            "headings on a lattice; grid: the same with turns of pi/2, positions on a grid. "
            "Each turns around near a wall."
        ),
    ] = "paper",
) -> None:
    """Record a database of a random wall-avoiding behaviour in WORLD (the paper's by default).

    The behaviour always reads the paper's 5 rays (-0.6 to 0.6 rad, noiseless); --rays, --fov
    and --range choose what is recorded, so one seed walks the same path with every layout.
    """
    from sensorimotor.files import check_writable
    from sensorimotor.sim.core import check_behaviour, check_noise, spread_layout
    from sensorimotor.sim.database import check_memory, save_database
    from sensorimotor.sim.database import generate as generate_db
    from sensorimotor.sim.world import load_world

    if steps < 1:
        raise InputError(f"--steps must be at least 1, got {steps}")
    layout = spread_layout(rays, fov, range_)
    check_noise(noise, noise_kind, dropout, motor_noise)
    check_behaviour(behaviour)
    w = load_world(world)
    out = out or default_name(w.name, seed, rays, fov, range_, noise, noise_kind, dropout,
                              motor_noise, behaviour)  # fmt: skip
    check_writable(out)
    check_memory(steps, 12 * (rays + 5))
    with progress(f"generate {w.name}: steps", steps) as update:
        db = generate_db(
            w,
            steps,
            seed,
            layout,
            noise_std=noise,
            progress=lambda n: update(n),
            noise_kind=noise_kind,
            dropout=dropout,
            motor_noise_std=motor_noise,
            behaviour=behaviour,
        )
    save_database(db, out)
    how = f", the {behaviour} behaviour" if behaviour != "paper" else ""
    err_console.print(
        f"wrote {out} ({steps:,} steps of {w.name}, seed {seed}, {layout.describe()}{how})"
    )


# the options of a recording's import (import-bag, import-rawlog): the rays kept of each scan
RecordedOut = Annotated[Path, typer.Option(help="Database (.npz) to write.")]
RecordedRays = Annotated[
    int, typer.Option(min=1, max=MAX_RAYS, help="Lasers (the encoders read 5).")
]
RecordedFov = Annotated[
    float, typer.Option(min=0, max=MAX_FOV, help="Angle from first to last ray (rad).")
]
RecordedRange = Annotated[
    float, typer.Option("--range", min=0, max=MAX_RANGE, help="Reading of no return (units).")
]


@app.command("import-bag")
@writes(files=("out",))
def import_bag(
    bag: Annotated[Path, typer.Argument(help="ROS 1 .bag, ROS 2 bag folder or .mcap file.")],
    out: RecordedOut,
    scan: Annotated[str, typer.Option(help="sensor_msgs/LaserScan topic.")] = "/scan",
    odom: Annotated[str, typer.Option(help="nav_msgs/Odometry topic (the poses).")] = "/odom",
    cmd: Annotated[
        str | None, typer.Option(help="Twist topic of the commands (default: odometry's motion).")
    ] = None,
    rays: RecordedRays = 5,
    fov: RecordedFov = 1.2,
    range_: Annotated[
        float | None,
        typer.Option(
            "--range",
            min=0,
            max=MAX_RANGE,
            help="Reading of no return (units; default: each scan's range_max).",
        ),
    ] = None,
    rate: Annotated[
        float | None, typer.Option(min=0, max=MAX_RATE, help="Rows/s (default: the scans').")
    ] = None,
    world: Annotated[str | None, typer.Option(help="World of the poses' frame.")] = None,
    frame: Annotated[str | None, typer.Option(help="Poses in this /tf frame (map).")] = None,
) -> None:
    """Make a database of a real robot's recording: laser scans, odometry (see sim/rosbag.py)."""
    from sensorimotor.files import check_writable
    from sensorimotor.sim import rosbag
    from sensorimotor.sim.database import save_database
    from sensorimotor.sim.world import load_world

    layout = rosbag.ray_layout(rays, fov, 10.0 if range_ is None else range_)
    w = load_world(world) if world is not None else None
    check_writable(out)
    topics = rosbag.BagTopics(scan, odom, cmd, frame)
    db = rosbag.import_bag(bag, topics, layout, rate, w, scan_range=range_ is None)
    save_database(db, out)
    err_console.print(f"wrote {out}: {rosbag.summary(db)}")


@app.command("import-rawlog")
@writes(files=("out",))
def import_rawlog(
    log: Annotated[Path, typer.Argument(help="MRPT rawlog (.rawlog, gzip or plain).")],
    out: RecordedOut,
    sensor: Annotated[
        str | None, typer.Option(help="Sensor label of the scans (default: the first scan's).")
    ] = None,
    rays: RecordedRays = 5,
    fov: RecordedFov = 1.2,
    range_: RecordedRange = 10.0,
    scale: Annotated[
        float,
        typer.Option(min=1e-6, max=MAX_SCALE, help="Units a metre (1: a unit is a metre)."),
    ] = 1.0,
    world: Annotated[
        str | None, typer.Option(help="World of the poses' frame (odometry from (0, 0, 0)).")
    ] = None,
) -> None:
    """Make a database of a real robot's MRPT rawlog: laser scans, odometry (see sim/rawlog.py)."""
    from sensorimotor.files import check_writable
    from sensorimotor.sim import rawlog, rosbag
    from sensorimotor.sim.database import save_database
    from sensorimotor.sim.world import load_world

    layout = rosbag.ray_layout(rays, fov, range_)
    w = load_world(world) if world is not None else None
    check_writable(out)
    db = rawlog.import_rawlog(log, layout, scale, sensor, w)
    save_database(db, out)
    err_console.print(f"wrote {out}: {rawlog.summary(db)}")


def _save_plot(fig, out: Path, svg: bool) -> None:
    from sensorimotor.sim.plots import save_figure

    for path in save_figure(fig, out, svg=svg):
        err_console.print(f"wrote {path}")


def _check_png(out: Path) -> Path:
    from sensorimotor.files import check_writable

    if out.suffix.lower() != ".png":
        raise InputError(f"{out}: --out must be a .png file")
    return check_writable(out)


@plot_app.command("world")
@writes(files=("out",))
def plot_world_cmd(
    worlds: Annotated[
        list[str],
        typer.Argument(help="Worlds, side by side: square, rooms1, rooms2, or .toml paths."),
    ],
    out: PlotOut = Path("worlds.png"),
    svg: PlotSvg = False,
) -> None:
    """Fig. 1: the walls of each WORLD, side by side."""
    from sensorimotor.sim.figures import worlds_figure
    from sensorimotor.sim.world import load_world

    _check_png(out)
    _save_plot(worlds_figure([load_world(w) for w in worlds]), out, svg)


@plot_app.command("trajectory")
@reads(data=DATABASE)
@writes(files=("out",))
def plot_trajectory_cmd(
    data: Annotated[
        list[Path], typer.Option(help="Database (.npz); repeat for panels side by side.")
    ],
    steps: Annotated[
        int, typer.Option(min=1, max=MAX_STEPS, help="Steps drawn from the start of each.")
    ] = 10_000,
    out: PlotOut = Path("trajectories.png"),
    svg: PlotSvg = False,
) -> None:
    """Fig. 2: the agent's path over the first STEPS rows of each database, in its world."""
    from sensorimotor.sim.database import load_database
    from sensorimotor.sim.figures import trajectories_figure

    if steps < 1:
        raise InputError(f"--steps must be at least 1, got {steps}")
    _check_png(out)
    _save_plot(trajectories_figure([load_database(p) for p in data], steps), out, svg)


@plot_app.command("perception")
@reads(data=DATABASE)
@writes(files=("out",))
def plot_perception_cmd(
    data: Annotated[Path, typer.Option(help="Database (.npz) to take the situations from.")],
    row: Annotated[
        list[int] | None,
        typer.Option(
            min=0,
            max=MAX_STEPS,
            help="Draw these rows instead of the five situations; repeatable.",
        ),
    ] = None,
    view: Annotated[
        float,
        typer.Option(
            min=0,
            max=MAX_VIEW,
            help="Half-width of the window around the agent (units); 0: all.",
        ),
    ] = 7.5,
    out: PlotOut = Path("perception.png"),
    svg: PlotSvg = False,
) -> None:
    """Fig. 3: what the agent perceives (a red dot a ray) in the paper's five situations.

    The situations (nothing, line, corner, wall at its left, wall end) are found in the
    database by pose and readings; a wall end needs a world with inner walls (rooms1).
    """
    from sensorimotor.sim.database import load_database
    from sensorimotor.sim.figures import perception_figure, pick_situations

    if not (view >= 0 and math.isfinite(view)):
        raise InputError(f"--view must be a non-negative number, got {view}")
    _check_png(out)
    db = load_database(data)
    if row:
        bad = [r for r in row if not 0 <= r < len(db)]
        if bad:
            raise InputError(f"{data}: row {bad[0]} is outside the database (0..{len(db) - 1})")
        situations = {f"row {r}": r for r in row}
    else:
        situations = pick_situations(db)
        if not situations:
            raise InputError(f"{data}: none of the paper's five situations occurs in it")
    _save_plot(perception_figure(db, situations, view=view or None), out, svg)
