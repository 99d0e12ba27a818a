"""Do the paper's findings need its random walk? ``reproduce --experiment behaviour``.

Every claim of the paper was tested under one behaviour, a random walk that draws a new turn
each step. This records Square under a second one, the smooth random motion of
``sim.core.smooth_behaviour`` (an Ornstein-Uhlenbeck turning rate, the paper's speeds and wall
reflex; ``generate --behaviour smooth``), trains S, SM, Rec-S and Rec-SM on it with the
reproduction's steps, seeds, epoch caps and patience, and tests the three findings the scaling
experiment tests, with its thresholds (``scaling_report.verdicts``, ``analysis.claims``'
own): the ordering of Table I on Square, the corner cluster, the memory. The stages are the
scaling experiment's (``scaling.run_conditions``, cached under ``OUT/behaviour/``); the
paper's behaviour is the reproduction's own Square runs and analyses, at the same scale, read
through the same ``scaling.condition_numbers``, so that the two columns differ by the
behaviour alone.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from sensorimotor.analysis.claims import claim_numbers
from sensorimotor.errors import InputError
from sensorimotor.experiments.scaling import Condition, Size, condition_numbers, run_conditions
from sensorimotor.experiments.scaling_report import condition_table, finite
from sensorimotor.learn.runs import count
from sensorimotor.report.blocks import Block, h, image, p, table
from sensorimotor.sim.core import SMOOTH_A, SMOOTH_SD, SMOOTH_TAU
from sensorimotor.stats import word

WORLD = "square"  # Table I's training world, where the corner and memory claims are made
SMOOTH = Condition("smooth", "the smooth behaviour, Square", world=WORLD, behaviour="smooth")
PAPER = Condition("paper", "the paper's behaviour, Square (the reproduction's runs)", world=WORLD)
TRAJECTORY_STEPS = 2_000  # drawn of each database in the figure
WHERE = (
    "analysis/claims.py's thresholds for Square (commits d9848fc and 2f8a662, before the first "
    "published reproduction), taken over unchanged by experiments/behaviour.py before any "
    "model was trained on the smooth behaviour"
)
CORNER_BEYOND = "Motors grow a corner cluster"  # pipeline.paper.Scale.beyond's wording


def check(rep) -> None:
    """Refuse a reproduction without Square (the paper's behaviour's runs to compare with)."""
    if WORLD not in rep.worlds:
        raise InputError(
            f"experiment behaviour: its reference is the paper's behaviour's {WORLD} runs: "
            f"add {WORLD} to --worlds"
        )


def paper_numbers(rep) -> dict:
    """The reproduction's own Square runs as a condition (``scaling.condition_numbers``): their
    Table I errors on Square's test split, the raw readings' and their analyses' claim numbers."""
    runs = [r for r in rep.runs if r[0] == WORLD]
    evals = [r for r in rep.table["runs"] if r["trained_on"] == WORLD]
    numbers = claim_numbers(rep.analyses, runs, [WORLD])[WORLD]
    base = [rep.table["baselines"][WORLD]]
    return condition_numbers(PAPER, evals, [WORLD], [], base, numbers)


def motion(path: Path) -> dict:
    """``sim.motion.motion_statistics`` of a database's commands, strict JSON (None for NaN)."""
    from sensorimotor.sim.database import load_database
    from sensorimotor.sim.motion import motion_statistics

    stats = motion_statistics(load_database(path).motors)
    return {k: finite(v) if isinstance(v, float) else v for k, v in stats.items()}


def plot_trajectories(paths: dict[str, Path], out: Path) -> Path:
    """The first ``TRAJECTORY_STEPS`` poses of each behaviour's database, side by side."""
    import matplotlib

    matplotlib.use("Agg")
    from sensorimotor.sim.database import load_database
    from sensorimotor.sim.figures import trajectories_figure
    from sensorimotor.sim.plots import save_figure

    fig = trajectories_figure([load_database(p) for p in paths.values()], TRAJECTORY_STEPS)
    for ax, name in zip(fig.axes, paths, strict=True):
        ax.set_title(f"{name} behaviour: {TRAJECTORY_STEPS:,} steps")
    save_figure(fig, out)
    return out


def run(ctx) -> dict:
    """The smooth behaviour's condition trained, tested and analysed; the paper's read from
    the reproduction; the verdicts, the motion statistics and the figure."""
    rep = ctx.rep
    check(rep)
    size = Size.of(rep)
    found = run_conditions(ctx, size, [SMOOTH], getattr(rep, "device", "cpu"))
    conds = {PAPER.name: paper_numbers(rep), **found["conditions"]}
    for c in conds.values():
        c["verdicts"] = [{**v, "where": WHERE} for v in c["verdicts"]]
    paths = {PAPER.name: Path(rep.data[WORLD]), SMOOTH.name: ctx.dir / "data" / "smooth.npz"}
    plot_trajectories(paths, ctx.dir / "trajectories.png")
    ctx.log(f"  behaviour: {found['jobs']}")
    return {
        "size": asdict(size),
        "smooth": {"tau_steps": SMOOTH_TAU, "lag1": SMOOTH_A, "sd_rad": SMOOTH_SD},
        "motion": {name: motion(path) for name, path in paths.items()},
        "conditions": conds,
        "jobs": found["jobs"],
    }


def _f(v, digits: int = 2) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def _cell(cond: dict, claim: str) -> str:
    """A condition's verdict on ``claim`` in a cell: "holds (numbers)"."""
    v = next(v for v in cond["verdicts"] if v["claim"] == claim)
    return f"{word(v['holds'], 'holds', 'fails')} ({v['numbers']})"


def section(rep, found: dict) -> list[Block]:
    """The report's section: the two behaviours' motion, their tables, a verdict per finding
    and behaviour, and where the verdicts differ."""
    size, conds, moves = found["size"], found["conditions"], found["motion"]
    blocks = [
        h(2, "A second behaviour: the paper's findings under a smooth random motion"),
        p(
            "The smooth behaviour (`generate --behaviour smooth`) turns by a rate that follows "
            f"an Ornstein-Uhlenbeck process (mean 0, time constant {SMOOTH_TAU:g} steps, "
            f"stationary sd {SMOOTH_SD:.3f} rad: the heading diffuses as fast as under the "
            "paper's walk over many steps), goes forward by a speed drawn each step from "
            "U(0, 1) (the paper's) and turns around, as the paper's, when a reading is below 1. "
            f"S, SM, Rec-S and Rec-SM trained on Square under it ({size['steps']:,}-step "
            f"database, {count(size['seeds'], 'seed')}, patience {size['patience']}), beside "
            "the reproduction's own Square runs under the paper's behaviour, at the same scale. "
            "Errors are Table I's on each database's test split; corner F1 and the memory "
            "numbers are `analysis.claims`', as in the scaling experiment."
        ),
        table(
            [
                "Behaviour",
                "reflex steps",
                "turn lag-1 autocorrelation",
                "turn sd (rad)",
                "speed mean [min, max]",
            ],
            [
                [
                    name,
                    f"{_f(m['reflex_share'], 3)}",
                    _f(m["turn_lag1_autocorrelation"]),
                    _f(m["turn_sd"], 3),
                    f"{_f(m['speed_mean'])} [{_f(m['speed_min'])}, {_f(m['speed_max'])}]",
                ]
                for name, m in moves.items()
            ],
        ),
    ]
    picture = Path(rep.out) / "behaviour" / "trajectories.png"
    if picture.exists():
        blocks.append(image(picture, "The first steps of each behaviour's Square database"))
    for name, c in conds.items():
        blocks += [h(3, f"{name}: {c['label']}"), condition_table(c)]
    first = next(iter(conds.values()))["verdicts"]
    rows = [[v["claim"], *(_cell(c, v["claim"]) for c in conds.values())] for v in first]
    thresholds = "; ".join(f"**{v['claim']}**: {v['threshold']}" for v in first)
    blocks += [
        h(3, "Verdicts"),
        p(
            f"Each finding holds when its threshold is met: {thresholds}. Means over seeds "
            "compared, no test of significance. "
            f"Thresholds {first[0]['provenance']}: {first[0]['where']}."
        ),
        table(["Finding", *conds], rows),
    ]
    holds = {name: {v["claim"]: v["holds"] for v in c["verdicts"]} for name, c in conds.items()}
    changed = [
        f"{claim} ({word(holds[PAPER.name][claim], 'holds', 'fails')} under the paper's, "
        f"{word(holds[SMOOTH.name][claim], 'holds', 'fails')} under the smooth one)"
        for claim in holds.get(PAPER.name, {})
        if SMOOTH.name in holds and holds[SMOOTH.name].get(claim) != holds[PAPER.name][claim]
    ]
    note = (
        "The verdicts differ between the behaviours for: " + "; ".join(changed) + "."
        if changed
        else "Every finding has the same verdict under both behaviours."
    )
    if any(b.startswith(CORNER_BEYOND) for b in rep.scale.beyond):
        note += (
            f" At `--scale {rep.scale.name}` the corner cluster is not expected even under the "
            "paper's behaviour (the scale's stated limit): its verdict here says nothing of "
            "the paper's scale."
        )
    blocks.append(p(note))
    return blocks


__all__ = ["check", "run", "section"]
