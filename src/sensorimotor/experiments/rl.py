"""``reproduce --experiment rl``: do the reproduction's own representations help an agent act?

The paper's conclusion plans a reinforcement-learning test of the representations. This
experiment runs ``sensorimotor rl``'s grid (``rl.runner.run_grid``: the same PPO on every
feature set, many seeds, confidence intervals over seeds) on the three tasks in Rooms1, with
the encoders this reproduction trained on Rooms1 (``rep.run_dir("rooms1", model, seed)``; RL
seed k on encoder seed k), and evaluates every final policy unchanged in Square and Rooms2
(those that can hold the task: ``doorway`` needs two named rooms, Square names one). Its
agents are jobs of the reproduction's job runner; each task's grid lives in
``OUT/rl/{task}__{key}/``, ``key`` a hash of everything its agents depend on (the PPO and
evaluation settings, the bytes of every encoder's weights, the package version): a rerun trains
nothing, a retrained encoder gets new agents.

The report's headline score is the *stochastic* policy's success (``rl.results.HEADLINE``:
DESIGN.md says why); the deterministic one is shown beside it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sensorimotor.errors import InputError
from sensorimotor.files import file_hash
from sensorimotor.jobs.cache import stage_key
from sensorimotor.learn.runs import count
from sensorimotor.report.blocks import Block, h, image, p, table
from sensorimotor.rl.results import (
    CLAIM,
    HEADLINE,
    MIN_SEEDS,
    THRESHOLD,
    fmt_ci,
    spread_range,
    verdict_holds,
)
from sensorimotor.stats import BEFORE, CHOSEN, word
from sensorimotor.version import __version__

WORLD = "rooms1"  # where the agents learn, on encoders trained there
TRANSFER = ("square", "rooms2")  # where the final policies are also evaluated


OWN_EXPERIMENT = ("homing",)
"""Tasks left out of this grid: ``homing`` asks for a memory and its oracle ``pose+raw`` and
Rec-SMA (issue 37: an experiment of its own)."""
NOT_IN_GRID = ("pose+raw",)  # homing's oracle: no other task needs it


def tasks() -> tuple[str, ...]:
    """The grid's tasks: every registered one (``envs.tasks.TASKS``, read now) but those of
    ``OWN_EXPERIMENT``."""
    from sensorimotor.rl.runner import TASKS

    return tuple(t for t in TASKS if t not in OWN_EXPERIMENT)


def features() -> tuple[str, ...]:
    """The grid's feature sets: every one (``rl.features.feature_sets()``, read now) whose
    encoder, if any, the reproduction's paper stages train (``Kind.paper``), but
    ``NOT_IN_GRID``."""
    from sensorimotor.learn.models import KINDS
    from sensorimotor.rl.features import feature_sets

    return tuple(
        name
        for name, f in feature_sets().items()
        if name not in NOT_IN_GRID and (not f.trained or KINDS[f.kind].paper)
    )


def encoders() -> tuple[str, ...]:
    """The feature sets read from the reproduction's runs: one per paper model kind."""
    from sensorimotor.rl.features import feature_sets

    sets = feature_sets()
    return tuple(sets[f].kind for f in features() if sets[f].trained)


@dataclass(frozen=True)
class Plan:
    """How big the grid is at one reproduction scale (seeds: the reproduction's own)."""

    steps: int
    eval_every: int
    eval_episodes: int
    ppo: dict | None = None  # PPO arguments other than RLConfig's (None: RLConfig's)
    longer: dict | None = None  # {task: (steps, eval_every)} where ``steps`` teach nothing

    def budget(self, task: str) -> tuple[int, int]:
        """(steps, eval_every) of ``task``'s agents."""
        return (self.longer or {}).get(task, (self.steps, self.eval_every))


# explore: no agent learns it in 40,000 steps; in 500,000 every laser-reading feature set does
# (docs/results/rl/rooms1_grid/explore_500k)
EXPLORE = {"explore": (500_000, 125_000)}
PLANS = {
    # a smoke test of the pipeline: one 512-step rollout per agent, 10 evaluation episodes
    "smoke": Plan(512, 512, 10, {"n_steps": 64, "batch_size": 64, "n_epochs": 2}),
    "quick": Plan(40_000, 20_000, 50, longer=EXPLORE),  # docs/results/rl/rooms1_grid (no bonus)
    "paper": Plan(100_000, 25_000, 50, longer=EXPLORE),  # docs/results/rl/rooms1_full
}


def plan_for(scale_name: str) -> Plan:
    """The grid's size at a reproduction scale (an unknown scale: ``quick``'s)."""
    return PLANS.get(scale_name, PLANS["quick"])


def _check_world(rep) -> None:
    if WORLD not in tuple(rep.worlds):
        raise InputError(
            "experiment rl: needs the encoders trained on rooms1; add rooms1 to --worlds"
        )


def check(rep) -> None:
    """Refuse, before any stage, a reproduction without rooms1 in --worlds or without the
    ``[rl]`` extra (stable-baselines3): the agents learn on the Rooms1 encoders."""
    from sensorimotor.rl import check_extra

    _check_world(rep)
    check_extra()


def configs(rep) -> dict:
    """``{task: RLConfig}`` of the grid: encoders from ``rep``'s Rooms1 runs, sized by
    ``rep.scale``. InputError (one line) when Rooms1 was not trained or a run is missing."""
    from sensorimotor.rl.features import run_folder
    from sensorimotor.rl.runner import RLConfig, worlds_holding

    _check_world(rep)
    kinds = encoders()
    runs = Path(rep.run_dir(WORLD, kinds[0], 0)).parent
    for model in kinds:
        for seed in range(rep.seeds):
            folder = Path(rep.run_dir(WORLD, model, seed))
            if folder != run_folder(runs, WORLD, model, seed) or not folder.is_dir():
                raise InputError(f"experiment rl: no {model} run on {WORLD} at {folder}")
    plan = plan_for(rep.scale.name)
    ppo = {**RLConfig().ppo, **(plan.ppo or {})}
    settings = {
        "world": WORLD, "features": features(), "seeds": rep.seeds,
        "runs": str(runs), "trained_on": WORLD,
        "eval_episodes": plan.eval_episodes, "ppo": ppo,
    }  # fmt: skip
    return {
        task: RLConfig(
            task=task,
            transfer=worlds_holding(task, TRANSFER),
            steps=plan.budget(task)[0],
            eval_every=plan.budget(task)[1],
            **settings,
        )
        for task in tasks()
    }


def grid_key(config) -> str:
    """A short hash of what a grid's agents depend on: their settings, the weights (by bytes)
    of every trained encoder among ``config.features``, the package version (``homing``'s
    grid too)."""
    from sensorimotor.rl.features import feature_sets, run_folder

    sets = feature_sets()
    weights = {
        f"{kind}__s{seed}": file_hash(run_folder(config.runs, config.trained_on, kind, seed) / "model.pt")
        for kind in (sets[f].kind for f in config.features if sets[f].trained)
        for seed in range(config.seeds)
    }
    described = {
        "config": {**config.agent_config(), "runs": None},  # where the runs are: not an input
        "features": list(config.features),
        "seeds": config.seeds,
        "weights": weights,
        "version": __version__,
    }
    return stage_key(described)


def run(ctx) -> dict:
    """Every task's grid (cached), its agents as jobs of ``ctx.run_jobs``; the numbers."""
    from sensorimotor.rl import check_extra

    check_extra()
    from sensorimotor.jobs.backend import run_all
    from sensorimotor.rl.runner import run_grid

    tasks = {}
    for task, config in configs(ctx.rep).items():
        folder = ctx.dir / f"{task}__{grid_key(config)}"

        def run_agents(jobs, task=task):
            ctx.log(f"rl {task}: {len(jobs)} agents to train")
            return run_all(ctx.run_jobs, ctx.workers, jobs, ctx.progress)

        rl = run_grid(config, folder, run_agents=run_agents)
        for r in rl["results"].values():
            del r["curve"]  # in the folder's rl.json and figure
        tasks[task] = {"folder": folder.relative_to(ctx.rep.out).as_posix(), "rl": rl}
    plan = plan_for(ctx.rep.scale.name)
    return {
        "headline": HEADLINE,
        "world": WORLD,
        "seeds": ctx.rep.seeds,
        "steps": {task: plan.budget(task)[0] for task in tasks},
        "eval_episodes": plan.eval_episodes,
        "tasks": tasks,
    }


# --- the report section ----------------------------------------------------------------------

MEANING = (
    'What "features learned with motors help the agent more than raw readings" can and '
    "cannot mean: every encoder here (SM and Rec-SM alike) computes z_s from the readings "
    "alone (the motor commands enter its predictor, not z_s), and the feed-forward ones from "
    "the current readings only, so SM's features hold no information that the raw readings "
    "of the same step lack. A win of sm over raw can only be ease of learning (a "
    "representation on which PPO finds a good policy sooner at this budget), not "
    "information; a recurrent encoder (rec-s, rec-sm) may add information from the past "
    "readings, never from the commands. Whether raw catches up with more steps is what the "
    "longer learning curves ask."
)
INTERVALS = (
    "Intervals: below 10 seeds the verdicts read the Student-t interval of the paired "
    "per-seed differences (a percentile bootstrap of a handful of seeds only resamples what "
    "it saw and is too narrow); the bootstrap (stratified as rliable's, one task one stratum) "
    "is shown beside it, and from 10 seeds it is the one read. Each verdict says its "
    "provenance: set before the data, or chosen on these data (explore's entropy bonus, "
    "chosen on the agents it reports, until fresh seeds 5-9 confirm it)."
)

SCORES = {HEADLINE: "stochastic", "success": "deterministic"}


def _ci(s: dict) -> str:
    return fmt_ci(s)


def _diff(d: dict) -> str:
    return fmt_ci(d, "+")


def _interval(rl: dict) -> str:
    """What the table's brackets are: the 95 % interval ``stats.interval`` chose (rl.json
    written before it: the bootstrap)."""
    if rl["seeds"] < 2:
        return "mean, IQM; one seed: no interval"
    first = next(iter(rl["results"].values()))[HEADLINE]
    if first.get("t_ci_low") is not None:
        return "mean [95 % Student-t CI; 95 % percentile bootstrap CI], IQM"
    return f"mean [95 % {first.get('interval', 'bootstrap')} CI], IQM"


def _provenance(v: dict) -> str:
    """A verdict's provenance in words (rl.json before ``stats.Verdict``: set before)."""
    if v.get("provenance") == CHOSEN:
        return f" Provenance: {CHOSEN} ({v['where'].split('; threshold:')[0]})."
    return f" Provenance: {BEFORE}."


def verdict_lines(rl: dict, score: str = HEADLINE) -> list[tuple[str, bool | None]]:
    """The verdicts of one task's ``rl.json`` on ``score``, each a sentence and whether it
    holds (None: not judged): the sanity check "pose clearly above random", the paper's
    expectation, and whether the motor-trained encoders beat the untrained one too (else the
    help is not learned). All read the 95 % CI of paired per-seed differences
    (``rl.results.verdicts``: Student-t below 10 seeds, bootstrap from 10); with fewer than
    ``MIN_SEEDS`` seeds neither is judged."""
    how = SCORES.get(score, score)
    v = rl["verdicts"][score]
    if rl["seeds"] < MIN_SEEDS:
        why = f"{rl['seeds']} seed(s): no verdict below {MIN_SEEDS} seeds"
        return [(f"pose clearly above random ({how}): {why}.", None),
                (f"{CLAIM} ({how}): {why}.", None)]  # fmt: skip
    lines = []
    pose = v["pose_beats_random"]
    if verdict_holds(pose) is not None:
        held = word(verdict_holds(pose), "holds", "does NOT hold")
        lines.append(
            (
                f"pose clearly above random ({how} success; threshold: the 95 % CI of pose "
                f"minus random, paired by seed, above 0): {held}, {_diff(pose['difference'])}."
                + _provenance(pose),
                verdict_holds(pose),
            )
        )
        if verdict_holds(pose) is False:
            why = "no verdict: the agents on the true pose do not beat random ones"
            lines.append((f"{CLAIM} ({how}): {why}.", None))
    motors = v["motors_help"]
    if verdict_holds(motors) is not None:
        held = word(verdict_holds(motors), "supported", "NOT supported")
        diffs = ", ".join(f"{f} - raw {_diff(d)}" for f, d in motors["differences"].items())
        threshold = motors.get("threshold", THRESHOLD)  # what the file was judged by
        lines.append(
            (
                f"{CLAIM} ({how} success; {threshold}): {held}: {diffs}." + _provenance(motors),
                verdict_holds(motors),
            )
        )
    learned = v.get("motors_beat_random", {"holds": None})
    if verdict_holds(learned) is not None:
        held = word(verdict_holds(learned), "holds", "does NOT hold")
        diffs = ", ".join(f"{f} - random {_diff(d)}" for f, d in learned["differences"].items())
        lines.append(
            (
                f"the motor-trained encoders also beat the untrained one, random ({how} "
                f"success; the same threshold against random): {held}: {diffs}."
                + _provenance(learned),
                verdict_holds(learned),
            )
        )
    return lines


def _task_blocks(rep, task: str, entry: dict) -> list[Block]:
    rl = entry["rl"]
    worlds = rl["transfer"]
    header = ["features", "success, stochastic (headline)", "IQM", "success, deterministic"]
    header += [f"{w}: stoch. / det." for w in worlds]
    header += ["return: stoch. / det.", "sd before standardisation"]
    rows = []
    for name, r in rl["results"].items():
        row = [name, _ci(r[HEADLINE]), f"{r[HEADLINE]['iqm']:.2f}", _ci(r["success"])]
        row += [
            f"{r['transfer'][w][HEADLINE]['mean']:.2f} / {r['transfer'][w]['success']['mean']:.2f}"
            for w in worlds
        ]
        row.append(f"{r['return_stochastic']['mean']:.2f} / {r['return']['mean']:.2f}")
        row.append(spread_range(r))
        rows.append(row)
    blocks = [
        h(3, f"{task} in {rl['world']}"),
        p(
            f"Final success rate over {count(rl['seeds'], 'seed')} "
            f"({_interval(rl)}) after "
            f"{rl['steps']:,} steps, {rl['eval_episodes']} evaluation episodes each; transfer: "
            f"the same policies, unchanged, in the other worlds (means); the mean return in "
            f"{rl['world']}. From "
            f"`{entry['folder']}/rl.json`."
        ),
        table(header, rows),
        image(
            Path(rep.out) / entry["folder"] / "rl.png",
            f"{task}: learning curves (solid: deterministic, dashed: stochastic) and final "
            "success per feature set, in Rooms1 and the transfer worlds",
        ),
    ]
    for score in SCORES:
        blocks += [p(text) for text, _ in verdict_lines(rl, score)]
    return blocks


def _steps(steps: dict) -> str:
    """Each task's agents' steps, e.g. "40,000 steps each (explore: 500,000)"."""
    values = list(steps.values())
    common = max(set(values), key=values.count)
    others = ", ".join(f"{task}: {n:,}" for task, n in steps.items() if n != common)
    return f"{common:,} steps each" + (f" ({others})" if others else "")


def section(rep, found: dict) -> list[Block]:
    """Per task: success per feature set with its CI, transfer, learning curves, verdicts."""
    blocks = [
        h(2, "Does a representation help an agent act? (reinforcement learning)"),
        p(
            "The paper's conclusion plans to use the learned representations in a "
            "reinforcement-learning task. The same PPO (stable-baselines3) learns from each "
            "feature set: the true pose (oracle), the raw readings, the z_s of this "
            "reproduction's frozen Rooms1 encoders (RL seed k on encoder seed k), and an "
            f"untrained Recurrent-SM encoder (random), {found['seeds']} seed(s), "
            f"{_steps(found['steps'])}. Headline score: the success rate of the policy "
            "PPO trains, with its actions sampled (stochastic); the mean action "
            "(deterministic) is shown beside it: it rewards reflexes such as driving "
            "straight, and can fail the sanity check that the oracle beats an untrained "
            "encoder (DESIGN.md, Reinforcement learning). Every feature set reaches the "
            "policy standardised per dimension by the statistics of a rollout taken before "
            "training, frozen (the table gives each set's sd before it, lowest-highest)."
        ),
        p(MEANING),
        p(INTERVALS),
    ]
    for task, entry in found["tasks"].items():
        blocks += _task_blocks(rep, task, entry)
    return blocks
