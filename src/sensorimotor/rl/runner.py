"""``sensorimotor rl``: PPO on each feature set and seed, evaluated as it learns, into one folder.

One *agent* is one PPO policy: one feature set, one seed (which is also its encoder's seed,
``features.load_encoder``). The output folder holds, per agent, ``{features}__s{seed}/`` with
its ``result.json`` (learning curve, final and transfer scores), ``policy.zip`` and
TensorBoard logs (``tb/``, when tensorboard is installed); then ``rl.json`` (the statistics
over seeds, ``results.summary``) and ``rl.png`` (the learning curves). An agent whose
``result.json`` exists is not trained again: run the same command after a stop to go on (an
agent stopped half-way starts again from its beginning; it gives the same numbers).

Features: every agent sees its feature set standardised by the statistics of a rollout taken
before it trains (``rl.standardise``, ``standardisation_for``), frozen for its training,
evaluation and transfer; ``result.json`` keeps them, ``rl.json`` the per-dimension spread.

Evaluation: every ``eval_every`` steps, at the start and at the end, the deterministic policy
plays ``eval_episodes`` episodes on separate environments whose starts are the same for every
agent (seeded by ``EVAL_SEED``): a paired comparison across feature sets and time.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

from sensorimotor.envs.tasks import TASKS, LaserTaskEnv
from sensorimotor.errors import InputError
from sensorimotor.files import atomic_path, read_json, write_text_atomic
from sensorimotor.jobs.workers import progress_sender
from sensorimotor.learn.models import REC_SM
from sensorimotor.rl.features import (
    FeatureVecEnv,
    feature_sets,
    load_encoder,
    needs_runs,
    no_runs_error,
)
from sensorimotor.rl.results import HEADLINE, summary, verdicts
from sensorimotor.rl.standardise import STATS_SEED, STATS_STEPS, Standardisation
from sensorimotor.rl.standardise import fit as fit_standardisation
from sensorimotor.rl.vec_env import TaskVecEnv
from sensorimotor.sim.world import load_world
from sensorimotor.version import __version__

EVAL_SEED = 1_000_000  # the evaluation environments' seed: the same starts for every agent


@dataclass(frozen=True)
class RLConfig:
    """One experiment: a task in a world, PPO's settings, how it is evaluated."""

    task: str = "corner"
    """A task of ``envs.tasks.TASKS`` (corner, doorway, explore, homing)."""
    world: str = "rooms1"
    """The world the agents learn in."""
    features: tuple[str, ...] = ("pose", "raw", REC_SM, "random")
    """Feature sets, each learned by its own agents (``features.feature_sets()``)."""
    seeds: int = 3
    """Agents per feature set: seeds 0 .. seeds - 1 (and encoder seeds)."""
    steps: int = 100_000
    """Environment steps each agent learns for."""
    runs: str | None = None
    """Folder of trained encoder runs, named {world}__{kind}__s{seed}; needed by the trained
    feature sets (``features.needs_runs``), no default."""
    trained_on: str | None = None
    """The world the encoders were trained on (default: the task's world)."""
    transfer: tuple[str, ...] = ()
    """Worlds where the final policy is also evaluated, unchanged."""
    eval_every: int = 5_000
    """Steps between evaluations."""
    eval_episodes: int = 50
    """Episodes per evaluation (deterministic policy)."""
    n_envs: int = 8
    """Parallel environments PPO collects from."""
    stats_steps: int = STATS_STEPS
    """Steps of the rollout whose statistics standardise every feature set
    (``rl.standardise``); 0: the features as computed (the grids before issue 36)."""
    ppo: dict = field(
        default_factory=lambda: {
            "n_steps": 512,
            "batch_size": 128,
            "n_epochs": 10,
            "learning_rate": 3e-4,
            "gamma": 0.99,
            "gae_lambda": 0.95,
            "ent_coef": 0.01,  # 0.0 let the pose policy settle into a short loop on explore
        }
    )
    """stable-baselines3 PPO arguments (MlpPolicy, 2 x 64 tanh)."""

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise InputError(f"unknown task {self.task!r}: use one of {', '.join(TASKS)}")
        known = feature_sets()
        unknown = [f for f in self.features if f not in known]
        if unknown or not self.features:
            raise InputError(f"unknown features {unknown}: use some of {', '.join(known)}")
        for name in ("seeds", "steps", "eval_every", "eval_episodes", "n_envs"):
            if getattr(self, name) < 1:
                raise InputError(f"--{name.replace('_', '-')} must be at least 1")
        if self.stats_steps < 0:
            raise InputError("--stats-steps must be at least 0")
        object.__setattr__(self, "features", tuple(self.features))
        object.__setattr__(self, "transfer", tuple(self.transfer))
        object.__setattr__(self, "trained_on", self.trained_on or self.world)

    def agent_config(self) -> dict:
        """What one agent's numbers depend on (not which features or how many seeds)."""
        d = asdict(self)
        del d["features"], d["seeds"]
        return d


def make_env(
    config: RLConfig,
    world: str,
    features: str,
    encoder,
    n: int,
    seed: int,
    batched: bool = True,
    standardisation: Standardisation | None = None,
):
    """``n`` task environments in ``world`` behind ``FeatureVecEnv`` (seeded ``seed + i``;
    its observations standardised by ``standardisation`` where given): stepped together
    (``vec_env.TaskVecEnv``: one simulator call a step), or with ``batched=False`` one by one
    (``DummyVecEnv`` over ``gym.make``; the same numbers, slower: ``benchmarks/bench_rl.py``)."""
    load_world(world)  # a bad world name: InputError before any environment is made
    if batched:
        venv = TaskVecEnv(config.task, world, n)
        venv.seed(seed)
    else:
        venv = make_vec_env(
            TASKS[config.task].env_id, n_envs=n, seed=seed, env_kwargs={"world": world},
            vec_env_cls=DummyVecEnv,
        )  # fmt: skip
    return FeatureVecEnv(venv, features, encoder, standardisation)


def standardisation_for(
    config: RLConfig, features: str, encoder, seed: int
) -> Standardisation | None:
    """The frozen statistics agent ``seed`` of ``features`` sees its features through: a
    rollout of ``config.stats_steps`` steps in the task's world (``rl.standardise``); None
    when ``stats_steps`` is 0."""
    if not config.stats_steps:
        return None
    venv = make_env(config, config.world, features, encoder, config.n_envs, STATS_SEED + seed)
    return fit_standardisation(venv, config.stats_steps, seed)


def evaluate(model: PPO, venv: FeatureVecEnv, episodes: int, deterministic: bool = True) -> dict:
    """Success rate and mean return of ``episodes`` episodes of the policy (its mean action,
    or with ``deterministic=False`` actions sampled from it), shared among the environments
    (environment i plays ``episodes // n`` or one more); the environments are reseeded with
    ``EVAL_SEED`` first, so every call plays the same starts."""
    n = venv.num_envs
    quota = np.array([episodes // n + (i < episodes % n) for i in range(n)])  # (n,)
    venv.seed(EVAL_SEED)
    obs = venv.reset()
    played, running = np.zeros(n, dtype=int), np.zeros(n)
    successes, returns = [], []
    while (played < quota).any():
        actions, _ = model.predict(obs, deterministic=deterministic)
        obs, rewards, dones, infos = venv.step(actions)
        running += rewards
        for i in np.flatnonzero(dones):
            if played[i] < quota[i]:
                successes.append(float(infos[i]["is_success"]))
                returns.append(float(running[i]))
                played[i] += 1
            running[i] = 0.0
    return {"success": float(np.mean(successes)), "return": float(np.mean(returns))}


SCORES = ("success", "return", "success_stochastic", "return_stochastic")


def evaluate_both(model: PPO, venv: FeatureVecEnv, episodes: int) -> dict:
    """``evaluate`` of the deterministic policy (``success``, ``return``: what the issue and
    stable-baselines3's ``EvalCallback`` measure) and of the stochastic one (``*_stochastic``):
    a policy without memory that always takes its mean action can push against a wall for ever
    (same readings, same action), where its own sampled actions slide off it."""
    det = evaluate(model, venv, episodes)
    sto = evaluate(model, venv, episodes, deterministic=False)
    return {**det, "success_stochastic": sto["success"], "return_stochastic": sto["return"]}


class _Curve(BaseCallback):
    """Evaluates at step 0 and every ``every`` steps before ``steps`` into ``curve`` (the final
    evaluation, after the last update, is the caller's); reports the step count to
    ``progress``."""

    def __init__(self, venv, every: int, episodes: int, steps: int, progress: Callable):
        super().__init__()
        self.venv, self.every, self.episodes, self.progress = venv, every, episodes, progress
        self.steps = steps
        self.curve: dict[str, list] = {"steps": [], **{k: [] for k in SCORES}}
        self.next = 0

    def record(self) -> None:
        self.curve["steps"].append(int(self.num_timesteps))
        for key, value in evaluate_both(self.model, self.venv, self.episodes).items():
            self.curve[key].append(value)

    def _on_training_start(self) -> None:
        self.record()  # the untrained policy, at step 0
        self.next = self.every

    def _on_step(self) -> bool:
        if self.next <= self.num_timesteps < self.steps:
            self.record()
            self.next += self.every
        self.progress(int(self.num_timesteps))
        return True


def train_agent(
    config: RLConfig, features: str, seed: int, folder: Path, progress: Callable[[int], None]
) -> dict:
    """Train one agent in ``folder`` (made anew); return its ``result.json`` content."""
    torch.set_num_threads(1)  # one core per agent; also makes the numbers reproducible
    start = time.perf_counter()
    encoder, encoder_run = load_encoder(features, _runs(config), config.trained_on, seed)
    scaled = standardisation_for(config, features, encoder, seed)
    venv = make_env(config, config.world, features, encoder, config.n_envs, seed, True, scaled)
    eval_envs = min(10, config.eval_episodes)
    eval_venv = make_env(
        config, config.world, features, encoder, eval_envs, EVAL_SEED, True, scaled
    )
    if folder.exists():
        shutil.rmtree(folder)  # what a stopped attempt left
    folder.mkdir(parents=True)
    tb = str(folder / "tb") if _has_tensorboard() else None
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu", tensorboard_log=tb, **config.ppo)
    curve = _Curve(eval_venv, config.eval_every, config.eval_episodes, config.steps, progress)
    model.learn(total_timesteps=config.steps, callback=curve, tb_log_name="ppo")
    curve.record()  # the final score (PPO learns whole rollouts: steps rounded up to one)
    transfer = {}
    for world in config.transfer:
        tvenv = make_env(config, world, features, encoder, eval_envs, EVAL_SEED, True, scaled)
        transfer[world] = evaluate_both(model, tvenv, config.eval_episodes)
    with atomic_path(folder / "policy.zip", ".zip") as tmp:
        model.save(tmp)
    c = curve.curve
    return {
        "features": features,
        "seed": seed,
        "encoder_run": encoder_run,
        "standardisation": None if scaled is None else scaled.to_dict(),
        "config": config.agent_config(),
        "version": __version__,
        "curve": c,
        "final": {k: c[k][-1] for k in SCORES},
        "transfer": transfer,
        "seconds": round(time.perf_counter() - start, 1),
    }


def _has_tensorboard() -> bool:
    import importlib.util

    return importlib.util.find_spec("tensorboard") is not None


def agent_folder(out: Path, features: str, seed: int) -> Path:
    return Path(out) / f"{features}__s{seed}"


def load_agent(path: Path, config: RLConfig) -> dict | None:
    """A finished agent's result, or None when there is none; InputError when it was made
    with other settings (another experiment in the same folder)."""
    if not path.is_file():
        return None
    result = read_json(path, "result of an agent")
    try:
        made_with = result["config"]
    except (KeyError, TypeError) as err:
        raise InputError(f"{path}: not an agent result ({err})") from None
    if made_with != json.loads(json.dumps(config.agent_config())):
        raise InputError(f"{path}: made with other settings; use another --out")
    stats = result.get("standardisation")
    if stats is not None and not _is_standardisation(stats):
        raise InputError(f"{path}: corrupt standardisation (mean and sd: equal lists of numbers)")
    return result


def _is_standardisation(stats) -> bool:
    """Whether an agent result's ``standardisation`` is what ``Standardisation.to_dict`` wrote."""
    try:
        mean, sd = np.asarray(stats["mean"], float), np.asarray(stats["sd"], float)
    except (KeyError, TypeError, ValueError):
        return False
    return mean.ndim == sd.ndim == 1 and mean.shape == sd.shape and bool((sd >= 0).all())


def worlds_holding(task: str, worlds: tuple[str, ...]) -> tuple[str, ...]:
    """Those of ``worlds`` where ``task`` can be set (``doorway`` needs two named rooms)."""
    held = []
    for world in worlds:
        try:
            LaserTaskEnv(task, load_world(world))
        except InputError:
            continue
        held.append(world)
    return tuple(held)


def _runs(config: RLConfig) -> Path | None:
    return None if config.runs is None else Path(config.runs)


def check_inputs(config: RLConfig) -> None:
    """Every InputError the grid can meet, before any agent trains: trained feature sets
    without a runs folder, a world that does not load or cannot hold the task, a missing or
    unfitting encoder run."""
    for world in (config.world, *config.transfer):
        LaserTaskEnv(config.task, load_world(world))
    missing = needs_runs(config.features)
    if missing and config.runs is None:
        raise no_runs_error(missing)
    for features in config.features:
        for seed in range(config.seeds):
            load_encoder(features, _runs(config), config.trained_on, seed)


# a job as the job runners of ``report`` take it: (name, function, arguments)
AgentJob = tuple[str, Callable, tuple]


def agent_job(
    config: RLConfig,
    features: str,
    seed: int,
    folder: str,
    report: Callable[[int], None] | None = None,
) -> dict:
    """Train one agent into ``folder`` and write its ``result.json``: the unit of work, in
    this process or as a job of a job runner (worker processes, Ray tasks: a top-level
    function, so that it pickles). ``report(steps_done)`` follows its training."""
    path = Path(folder) / "result.json"
    if report is None:  # a job of a runner: a line to its parent's log now and then
        send = progress_sender(path.parent.name)

        def report(n: int) -> None:
            send(f"{n:,} of {config.steps:,} steps", last=n >= config.steps)

    result = train_agent(config, features, seed, path.parent, report)
    write_text_atomic(path, json.dumps(result, indent=2, allow_nan=False))
    return result


def run_grid(
    config: RLConfig,
    out: Path,
    progress: Callable[[str, int, int], None] | None = None,
    run_agents: Callable[[list[AgentJob]], dict[str, dict]] | None = None,
) -> dict:
    """Train (or reuse) every agent of ``config`` in ``out``, write ``rl.json`` and ``rl.png``;
    return ``rl.json``'s content. ``progress(features, seed, steps_done)`` follows training in
    this process; ``run_agents`` (the command line passes one of ``report``'s job runners)
    trains the agents left as jobs instead, several at a time. Every agent is what it is
    trained alone: its seeds, its folder."""
    check_inputs(config)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[tuple[str, int], dict] = {}
    todo: list[AgentJob] = []
    for features in config.features:
        for seed in range(config.seeds):
            folder = agent_folder(out, features, seed)
            result = load_agent(folder / "result.json", config)
            if result is None and run_agents is not None:
                todo.append((folder.name, agent_job, (config, features, seed, str(folder))))
                continue
            if result is None:
                report = (
                    (lambda f, s: lambda n: progress(f, s, n))(features, seed) if progress else None
                )
                result = agent_job(config, features, seed, str(folder), report)
            elif progress:
                progress(features, seed, config.steps)
            results[features, seed] = result
    if todo:
        done = run_agents(todo)
        for _name, _fn, (_config, features, seed, _folder) in todo:
            results[features, seed] = done[_name]
    agents = {f: [results[f, s] for s in range(config.seeds)] for f in config.features}
    rl = aggregate(config, agents)
    write_text_atomic(out / "rl.json", json.dumps(rl, indent=2, allow_nan=False))
    from sensorimotor.rl.plots import plot_rl

    plot_rl(rl, out / "rl.png")
    return rl


def spread(agents: list[dict]) -> dict | None:
    """The per-dimension spread of a feature set before standardisation: each agent's rollout
    sd (``sd_per_seed``, seeds x F) and their mean over seeds (``sd``), the same for the
    means; None when the agents were not standardised."""
    stats = [r.get("standardisation") for r in agents]
    if any(s is None for s in stats):
        return None
    sd = np.array([s["sd"] for s in stats])  # (seeds, F)
    mean = np.array([s["mean"] for s in stats])
    return {
        "sd": [float(x) for x in sd.mean(0)],
        "mean": [float(x) for x in mean.mean(0)],
        "sd_per_seed": sd.tolist(),
        "steps": stats[0]["steps"],
    }


def aggregate(config: RLConfig, agents: dict[str, list[dict]]) -> dict:
    """``rl.json``: per feature set, the final success and return over seeds (``summary``), the
    learning curve (mean and CI at each evaluation) and the transfer scores; the task's
    memoryless baseline (``Task.no_memory``) where it has one."""
    results = {}
    no_memory = TASKS[config.task].no_memory  # the task's memoryless baseline, if it has one
    for features, rs in agents.items():
        curve_steps = rs[0]["curve"]["steps"]
        curve = {"steps": curve_steps}
        for key in SCORES:
            per_step = np.array([r["curve"][key] for r in rs])  # (seeds, evaluations)
            stats = [summary(per_step[:, j]) for j in range(per_step.shape[1])]
            curve[key] = {k: [s[k] for s in stats] for k in ("mean", "ci_low", "ci_high")}
        results[features] = {
            **{k: summary([r["final"][k] for r in rs]) for k in SCORES},
            "curve": curve,
            "transfer": {
                w: {k: summary([r["transfer"][w][k] for r in rs]) for k in SCORES}
                for w in config.transfer
            },
            "encoder_runs": [r["encoder_run"] for r in rs],
            "spread": spread(rs),
        }
    return {
        "task": config.task,
        "world": config.world,
        "trained_on": config.trained_on,
        "seeds": config.seeds,
        "steps": config.steps,
        "eval_episodes": config.eval_episodes,
        "transfer": list(config.transfer),
        "config": config.agent_config(),
        "version": __version__,
        "headline": HEADLINE,
        "results": results,
        "no_memory": None if no_memory is None else no_memory(config.world),
        "verdicts": {
            k: verdicts(results, k, config.task, config.ppo)
            for k in ("success", "success_stochastic")
        },
    }
