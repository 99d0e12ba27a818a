"""Does it scale? ``reproduce --experiment scaling``: the paper's four models on more rays, on
noisy readings and on generated floor plans never seen in training.

Conditions (``conditions``), each trained with S, SM, Rec-S and Rec-SM, the reproduction's
seeds, steps, epoch caps and patience (``Size.of``):

    rays5, rays16, rays64  Rooms2 with 5, 16 and 64 rays over the paper's field of view (1.2 rad)
                           and range (10): Rooms2 is the built-in world with the most walls, wall
                           ends and corners, so the most for more rays to see
    noise                  Rooms2, the paper's 5 rays, Gaussian reading noise and dropouts
    plans                  10 generated floor plans (``sim.floorplan``) for training, 10 others
                           for testing, every one 50 x 50 with 6 rooms

Stages, each cached under ``OUT/scaling/`` by a hash of its inputs (a rerun does only what is
missing or changed): ``data/`` (a database per condition, and per plan), ``runs/`` (every
model's seeds of one condition in one ``train.train_runs`` call), ``eval/`` (``evaluate_run``
on the condition's test databases), ``analysis/`` (``analyze_files`` of each run and of the
raw readings on each test database: the corner cluster, the corner probe (a class-balanced
logistic regression fitted on the database's training split, its AUC on the test split) and the
memory numbers of ``analysis.claims``). The 10 training plans make one database (``merge_plans``): the train
parts of the 10 plan databases one after the other, then their validation parts, then their
test parts, so that its splits are exactly the union of the plans' splits; its world is
unknown (rows of 10 worlds; training reads readings and commands alone).
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from sensorimotor.analysis.analyze import with_raw
from sensorimotor.errors import InputError
from sensorimotor.experiments.scaling_report import plot_errors, section, verdicts
from sensorimotor.files import file_hash, read_json, read_json_if_any, write_json_atomic
from sensorimotor.jobs.cache import read_key, stage_key
from sensorimotor.jobs.workers import Job
from sensorimotor.learn.models import KINDS, paper_kinds
from sensorimotor.learn.runs import run_name
from sensorimotor.pipeline.stages import analysis_job, eval_job, train_and_tell, train_config
from sensorimotor.stats import describe, mean_sd, present
from sensorimotor.version import __version__

WORLD = "rooms2"  # the built-in world of the ray and noise conditions (module docstring)
FOV, RANGE = 1.2, 10.0  # the paper's layout: 5 rays from -0.6 to 0.6 rad, range 10
PLANS = 10  # generated floor plans to train on, and as many others to test on
PLAN = {"rooms": 6, "size": 50.0, "door": 5.0, "min_side": 10.0}
"""The generated plans: as large as the paper's worlds, doorways as wide as Rooms2's openings
are at their narrowest (5 units: the behaviour turns at 1 unit from a wall)."""
TEST_PLAN_SEED = 1000  # test plans are seeds 1000..1009, training plans 0..9
NOISE_SD, DROPOUT = 0.3, 0.01  # units of reading noise (3 % of the range); rays dropped
EVENT_PROBES = "train split"  # the corner probe is fitted on each test database's training split


@dataclass(frozen=True)
class Condition:
    """One condition: the database(s) its models train on and are tested on."""

    name: str
    label: str
    rays: int = 5
    noise: float = 0.0
    dropout: float = 0.0
    plans: int = 0  # 0: the built-in ``world``; else train on these many plans, test on others
    world: str = WORLD  # the built-in world of a condition without plans
    behaviour: str = "paper"  # sim.core.BEHAVIOURS: what walks the robot (experiments.behaviour)

    def layout(self) -> dict:
        return {"rays": self.rays, "fov": FOV, "range": RANGE}


@dataclass(frozen=True)
class Size:
    """How big the experiment is: the reproduction's scale, or a test's."""

    steps: int  # rows of a condition's database (of the 10 training plans' together)
    seeds: int
    max_epochs: dict = field(default_factory=dict)
    patience: int = 10

    @staticmethod
    def of(rep) -> Size:
        sc = rep.scale
        caps = {kind: sc.epochs(kind) for kind in KINDS}  # the scale's epoch_cap too (smoke's 2)
        return Size(sc.steps, rep.seeds, caps, sc.patience)

    @property
    def plan_steps(self) -> int:
        """Rows of one plan's database: a tenth, a multiple of 10 so that splits line up."""
        return max(10, self.steps // PLANS // 10 * 10)


def conditions() -> list[Condition]:
    """The experiment's conditions, in the report's order."""
    return [
        Condition("rays5", "5 rays (the paper's layout), Rooms2", 5),
        Condition("rays16", "16 rays, Rooms2", 16),
        Condition("rays64", "64 rays, Rooms2", 64),
        Condition(
            "noise",
            f"5 rays, noise SD {NOISE_SD:g} units and {DROPOUT:.0%} dropouts, Rooms2",
            noise=NOISE_SD,
            dropout=DROPOUT,
        ),
        Condition("plans", f"{PLANS} generated plans, tested on {PLANS} unseen", plans=PLANS),
    ]


# --- jobs (module-level: they run in worker processes) ---------------------------------------


def plan_world(seed: int, name: str):
    """Generated plan ``seed`` (``PLAN``'s rooms and sizes), named ``name``."""
    from sensorimotor.sim.floorplan import random_plan

    size = PLAN["size"]
    return random_plan(PLAN["rooms"], seed, PLAN["door"], (size, size), PLAN["min_side"], name=name)


def _data_job(spec: dict, path: str, key: str) -> str:
    """One database: ``spec`` names the world (built-in, or a plan's seed) and the layout."""
    from sensorimotor.sim.core import spread_layout
    from sensorimotor.sim.database import generate, save_database
    from sensorimotor.sim.world import load_world

    world = spec["world"]
    world = load_world(world) if isinstance(world, str) else plan_world(**world)
    layout = spread_layout(spec["rays"], spec["fov"], spec["range"])
    db = generate(
        world,
        spec["steps"],
        spec["seed"],
        layout,
        spec["noise"],
        dropout=spec["dropout"],
        behaviour=spec.get("behaviour", "paper"),
    )
    save_database(db, path)
    write_json_atomic(Path(path).with_suffix(".json"), {"key": key})
    return path


def merge_plans(parts: Sequence[str], path: str, name: str) -> Path:
    """One database of the plan databases ``parts`` (equal lengths, one layout): their train
    parts, then their validation parts, then their test parts, so that each split is the
    union of theirs. Its ``meta.world`` names it alone (rows of several worlds have no one
    world's walls) and ``meta.source`` lists the plans."""
    from sensorimotor.sim.database import Database, load_database, save_database

    dbs = [load_database(p) for p in parts]
    if len({len(db) for db in dbs}) != 1 or len({db.layout for db in dbs}) != 1:
        raise InputError(f"{parts[0]}: plan databases merged must have one length and layout")
    arrays = [
        np.concatenate(
            [getattr(db.take(split), a) for split in ("train", "val", "test") for db in dbs]
        )
        for a in ("sensors", "motors", "poses")
    ]
    first = dbs[0].meta
    meta = {
        "format": first["format"],
        "world": {"name": name},
        "source": "the train, validation and test parts of "
        + ", ".join(db.meta["world"]["name"] for db in dbs)
        + " (each split the union of theirs)",
        "seed": [db.meta["seed"] for db in dbs],
        "steps": sum(len(db) for db in dbs),
        "sensor_layout": first["sensor_layout"],
        "noise_std": first["noise_std"],
        "behaviour": first["behaviour"],
        "version": __version__,
    }
    return save_database(Database(*arrays, meta=meta), path)


def _merge_job(parts: list[str], path: str, name: str, key: str) -> str:
    merge_plans(parts, path, name)
    write_json_atomic(Path(path).with_suffix(".json"), {"key": key})
    return path


def _train_job(data: str, runs: list[tuple[int, str]], config: dict, key: str) -> dict:
    """Every seed of one model on one database, in one ``train.train_runs`` call (stacked where
    it can); a run folder made from other inputs is cleared first, one of these inputs resumed."""
    for _, run_dir in runs:
        run = Path(run_dir)
        run.parent.mkdir(parents=True, exist_ok=True)
        if run.exists() and read_key(_mark(run)) != key:
            shutil.rmtree(run)
    write_marks = [_mark(r) for _, r in runs]
    for mark in write_marks:  # the inputs the folder is from, before it is written
        write_json_atomic(mark, {"key": key, "done": False})
    results = train_and_tell(data, runs, config)
    for mark in write_marks:
        write_json_atomic(mark, {"key": key, "done": True})
    return results


# --- the stages --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Plan:
    """Where one condition's files are, once its data stage has been planned."""

    cond: Condition
    train_data: Path
    test_data: list[Path]
    seen_data: list[Path] = field(default_factory=list)  # plans: the training plans' own


def _spec(cond: Condition, steps: int, world, seed: int) -> dict:
    """A database's specification, its cache key (the behaviour named only when not the
    paper's, so that the paper's databases keep their keys)."""
    return {
        "world": world,
        "steps": steps,
        "seed": seed,
        **cond.layout(),
        "noise": cond.noise,
        "dropout": cond.dropout,
        **({"behaviour": cond.behaviour} if cond.behaviour != "paper" else {}),
        "version": __version__,
    }


def _data_stage(ctx, size: Size, conds: Sequence[Condition]) -> tuple[list[Plan], list, list]:
    """Each condition's databases: (plans, jobs that make the missing ones, merge jobs)."""
    root = ctx.dir / "data"
    plans, jobs, merges = [], [], []

    def need(path: Path, spec: dict) -> None:
        key = stage_key(spec)
        if not (path.exists() and read_key(path.with_suffix(".json")) == key):
            jobs.append(Job(f"data {path.stem}", _data_job, (spec, str(path), key)))

    for cond in conds:
        if not cond.plans:
            path = root / f"{cond.name}.npz"
            need(path, _spec(cond, size.steps, cond.world, 0))
            plans.append(Plan(cond, path, [path]))
            continue
        parts = {"train": [], "test": []}
        for side, first in (("train", 0), ("test", TEST_PLAN_SEED)):
            for k in range(cond.plans):
                name = f"{cond.name}-{side}{k}"
                path = root / cond.name / f"{name}.npz"
                world = {"seed": first + k, "name": name}
                need(path, _spec(cond, size.plan_steps, world, k))
                parts[side].append(path)
        merged = root / f"{cond.name}.npz"
        spec = [_spec(cond, size.plan_steps, p.name, 0) for p in parts["train"]]  # not where
        key = stage_key({"merge": spec, "version": __version__})
        if not (merged.exists() and read_key(merged.with_suffix(".json")) == key) or any(
            job.name.startswith(f"data {cond.name}-") for job in jobs
        ):
            args = ([str(p) for p in parts["train"]], str(merged), f"{cond.name}-train", key)
            merges.append(Job(f"data {cond.name}", _merge_job, args))
        plans.append(Plan(cond, merged, parts["test"], parts["train"]))
    root.mkdir(parents=True, exist_ok=True)
    for plan in plans:
        plan.train_data.parent.mkdir(parents=True, exist_ok=True)
        for p in plan.test_data:
            p.parent.mkdir(parents=True, exist_ok=True)
    return plans, jobs, merges


def _mark(run_dir: str | Path) -> Path:
    """The file beside a run folder that says which inputs it is from and whether it is done."""
    return Path(run_dir).with_name(Path(run_dir).name + ".key.json")


def _trained(run_dir: str, key: str) -> bool:
    mark = read_json_if_any(_mark(run_dir), "stage record")
    return mark == {"key": key, "done": True} and (Path(run_dir) / "result.json").exists()


def _train_config(size: Size, model: str, device: str) -> dict:
    return train_config(model, device, size.max_epochs.get(model), size.patience)


def _run_dirs(ctx, cond: Condition, model: str, size: Size) -> list[tuple[int, str]]:
    return [(s, str(ctx.dir / "runs" / run_name(cond.name, model, s))) for s in range(size.seeds)]


def _train_jobs(ctx, size: Size, plans: list[Plan], device: str, hashes: dict) -> list[Job]:
    from sensorimotor.learn.models import ModelConfig

    jobs = []
    for plan in plans:
        for model in paper_kinds():
            config = _train_config(size, model, device)
            key = stage_key(
                {
                    "data": hashes[plan.train_data],
                    "train": config,
                    "model": ModelConfig(kind=model).to_dict(),
                }
            )
            runs = _run_dirs(ctx, plan.cond, model, size)
            done = all(_trained(r, key) for _, r in runs)
            if not done:
                name = f"{plan.cond.name}__{model}"
                jobs.append(Job(name, _train_job, (str(plan.train_data), runs, config, key)))
    return jobs


def _eval_targets(ctx, plan: Plan, size: Size) -> list[tuple[str, list[Path], Path]]:
    """(run folder, databases it is tested on, result file) for each run of a condition."""
    data = [*plan.test_data, *plan.seen_data]
    return [
        (run, data, ctx.dir / "eval" / f"{Path(run).name}.json")
        for model in paper_kinds()
        for _, run in _run_dirs(ctx, plan.cond, model, size)
    ]


def _analysis_targets(ctx, plan: Plan, size: Size) -> list[tuple[str, str, str, Path]]:
    """(kind, run folder or "raw", test database, output folder): every run and the raw
    readings on each test database."""
    out = []
    for db in plan.test_data:
        where = ctx.dir / "analysis"
        out.append(("raw", "raw", str(db), where / f"raw__{plan.cond.name}__on__{db.stem}"))
        for model in paper_kinds():
            for _, run in _run_dirs(ctx, plan.cond, model, size):
                out.append((model, run, str(db), where / f"{Path(run).name}__on__{db.stem}"))
    return out


def run_conditions(ctx, size: Size, conds: Sequence[Condition], device: str = "cpu") -> dict:
    """Every stage of ``conds`` (cached); their numbers by condition name, and ``jobs``: how
    many jobs each stage ran (0 when everything was kept)."""
    from sensorimotor.analysis import METRICS_VERSION
    from sensorimotor.analysis.claims import claim_numbers
    from sensorimotor.learn.evaluate import baselines
    from sensorimotor.sim.database import load_database

    ran = {}
    plans, jobs, merges = _data_stage(ctx, size, conds)
    ctx.run(jobs)
    ctx.run(merges)
    ran["data"] = len(jobs) + len(merges)
    paths = {p for plan in plans for p in (plan.train_data, *plan.test_data, *plan.seen_data)}
    hashes = {p: file_hash(p) for p in paths}

    jobs = _train_jobs(ctx, size, plans, device, hashes)
    ctx.run(jobs)
    ran["train"] = len(jobs)

    jobs = []
    for plan in plans:
        for run, data, out in _eval_targets(ctx, plan, size):
            key = stage_key(
                {"model": file_hash(Path(run) / "model.pt"), "data": [hashes[d] for d in data]}
            )
            if read_key(out) != key:
                out.parent.mkdir(parents=True, exist_ok=True)
                jobs.append(
                    Job(Path(run).name, eval_job, (run, [str(d) for d in data], str(out), key))
                )
    ctx.run(jobs)
    ran["evaluate"] = len(jobs)

    jobs = []
    for plan in plans:
        for _, run, data, out in _analysis_targets(ctx, plan, size):
            model = "raw" if run == "raw" else file_hash(Path(run) / "model.pt")
            key = stage_key(
                {
                    "model": model,
                    "data": hashes[Path(data)],
                    "version": __version__,
                    "metrics": METRICS_VERSION,
                    "event_probes": EVENT_PROBES,
                }
            )
            if not ((out / "metrics.json").exists() and read_key(out / "stage.json") == key):
                args = (run, data, str(out), None, key, True)  # event probes: train -> test
                jobs.append(Job(out.name, analysis_job, args))
    ctx.run(jobs)
    ran["analyze"] = len(jobs)

    found = {}
    for plan in plans:
        evals = [
            read_json(out, "evaluation")["result"] for _, _, out in _eval_targets(ctx, plan, size)
        ]
        tests = [load_database(p) for p in plan.test_data]
        test_names = [db.meta["world"]["name"] for db in tests]
        seen_names = [load_database(p).meta["world"]["name"] for p in plan.seen_data]
        base = [baselines(db) for db in tests]
        numbers: dict[str, dict[str, list]] = {k: {} for k in with_raw()}
        targets = _analysis_targets(ctx, plan, size)
        for db in plan.test_data:  # claims.claim_numbers of each test database's analyses
            mine = [(kind, run, out) for kind, run, data, out in targets if data == str(db)]
            analyses, runs = {}, []
            for kind, run, out in mine:
                seed = int(Path(run).name.rsplit("__s", 1)[1]) if kind != "raw" else 0
                analyses["raw__w" if kind == "raw" else run_name("w", kind, seed)] = read_json(
                    out / "metrics.json", "analysis"
                )
                if kind != "raw":
                    runs.append(("w", kind, seed))
            for kind, values in claim_numbers(analyses, runs, ["w"])["w"].items():
                for name, vals in values.items():
                    numbers[kind].setdefault(name, []).extend(vals)
        found[plan.cond.name] = condition_numbers(
            plan.cond, evals, test_names, seen_names, base, numbers
        )
    return {"conditions": found, "jobs": ran}


def _mean(values: list) -> float | None:
    """The mean of the numbers that are there (``stats.present``); None if none is."""
    values = present(values)
    return mean_sd(values)[0] if values else None


def condition_numbers(cond, evals, test_names, seen_names, base, numbers) -> dict:
    """One condition's numbers (strict JSON): each model's test error (mean and sd over seeds
    of its mean over the test databases), on the training plans too for ``plans``, the
    baselines, the claim numbers (means over seeds and test databases) and the verdicts."""
    errors, seen = {}, {}
    for kind in paper_kinds():
        mine = [e for e in evals if e["model"] == kind]
        values = [float(np.mean([e["errors"][w] for w in test_names])) for e in mine]
        errors[kind] = {**describe(values), "values": values}
        if seen_names:
            seen[kind] = float(np.mean([e["errors"][w] for e in mine for w in seen_names]))
    claims = {
        kind: {
            name: _mean(numbers[kind].get(name, []))
            for name in ("corner_f1", "corner_auc", "nothing_clusters", "behind_r2")
        }
        for kind in with_raw()
    }
    return {
        "label": cond.label,
        "condition": asdict(cond),
        "test_worlds": test_names,
        "seen_worlds": seen_names,
        "errors": errors,
        "errors_on_training_plans": seen or None,
        "copy_last": float(np.mean([b["copy_last"] for b in base])),
        "mean_baseline": float(np.mean([b["mean"] for b in base])),
        "claims": claims,
        "verdicts": [
            v.to_dict() for v in verdicts({k: v["mean"] for k, v in errors.items()}, claims)
        ],
    }


def run(ctx) -> dict:
    """The experiment at the reproduction's scale (``reproduce``'s hook)."""
    size = Size.of(ctx.rep)
    found = run_conditions(ctx, size, conditions(), getattr(ctx.rep, "device", "cpu"))
    plot_errors(found["conditions"], ctx.dir / "errors.png")
    ctx.log(f"  scaling: {found['jobs']}")
    return {"size": asdict(size), "plan": PLAN, **found}


__all__ = ["run", "section", "verdicts"]
