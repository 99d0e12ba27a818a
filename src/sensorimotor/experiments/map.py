"""``reproduce --experiment map``: the map of each representation on each trained world.

For every trained world and every representation there, raw (the readings, the baseline) and
each trained run (model x seed), one job fits the map (``analysis.mapping.map_files``: cells,
the cell graph, the cloned HMM, its numbers and figures) into ``OUT/map/{name}/``, cached by a
hash of its inputs (the model's and the database's bytes, the map's settings, the version).
Raw has no seeds of its own: it is mapped once per seed of the reproduction with that seed
(k-means, EM and the planner's start/goal pairs), so its spread is the map's own; a trained
run is mapped with its own seed, so its spread is the representation's and the map's together.

Numbers aggregate over seeds as mean and sample sd (``stats.describe``: n - 1; 0 with n = 1,
shown without ±). Three claims (each a ``stats.Verdict``, its margin set before the data) are
judged per world and representation on the **paired** per-seed difference (the same
seed, the same test split), each with a minimum effect ``MARGINS``:

- *the map predicts the next cell better than first-order Markov*: bits/step markov - map;
- *the map localises the room better than its cells*: balanced room accuracy map - cells
  (balanced: a read-out that always names the biggest room is not credited);
- *the planner beats the random behaviour*: planning success map - random.

A claim **holds** when the mean difference exceeds its margin and, with two seeds or more,
2 standard errors over seeds (sd / sqrt(n)); for planning, whose rates come from a finite
number of start/goal pairs, 2 standard errors that are at least the binomial one, also with one
seed. It is **n/a** where the number is (a world without named rooms, no planning pairs).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sensorimotor.analysis.analyze import short_name, with_raw
from sensorimotor.files import file_hash, read_json, write_json_atomic
from sensorimotor.jobs.cache import read_key, stage_key
from sensorimotor.jobs.workers import Job
from sensorimotor.learn.models import KINDS
from sensorimotor.report.blocks import h, image, p, table
from sensorimotor.stats import (
    BEFORE,
    CHOSEN,
    Verdict,
    describe,
    mean_sd,
    paired_differences,
    standard_error,
    t_interval,
    word,
)
from sensorimotor.version import __version__

PAIRS = {
    "smoke": 10,
    "quick": 100,
}  # planning start/goal pairs by scale; otherwise planning.N_PAIRS
STAGE_VERSION = 8  # bump when the map's numbers change for the same inputs (8: Louvain runs)

CEIL = "ceiling.localisation."
# (key in the aggregate, path in map.json (None: a ratio of OF_CEILING), row label, format)
METRICS = (
    ("bits.unigram", "bits_per_step.unigram", "bits/step: unigram", ".3f"),
    ("bits.markov", "bits_per_step.markov", "bits/step: Markov (cell, action)", ".3f"),
    ("bits.markov2", "baselines.bits_per_step.markov2", "bits/step: 2nd-order Markov", ".3f"),
    ("bits.markov3", "baselines.bits_per_step.markov3", "bits/step: 3rd-order Markov", ".3f"),
    ("bits.rnn", "baselines.bits_per_step.rnn", "bits/step: GRU on (cell, action)", ".3f"),
    ("bits.hmm", "baselines.bits_per_step.hmm", "bits/step: plain HMM, as many states", ".3f"),
    ("bits.cell_graph", "bits_per_step.cell_graph", "bits/step: cell graph", ".3f"),
    ("bits.map_em", "bits_per_step.map_em", "bits/step: map after EM (unsplit)", ".3f"),
    ("bits.map", "bits_per_step.map", "bits/step: map", ".3f"),
    ("room.map", "localisation.room_accuracy.map", "room accuracy: map", ".3f"),
    ("room.cells", "localisation.room_accuracy.cells", "room accuracy: cells", ".3f"),
    ("room.chance", "localisation.room_accuracy.chance", "room accuracy: chance", ".3f"),
    ("broom.map", "localisation.balanced_room_accuracy.map", "balanced room acc.: map", ".3f"),
    ("broom.cells", "localisation.balanced_room_accuracy.cells", "balanced: cells", ".3f"),
    ("broom.chance", "localisation.balanced_room_accuracy.chance", "balanced: chance", ".3f"),
    ("broom.readout", "baselines.localisation.history_readout", "balanced: read-out", ".3f"),
    ("broom.ceiling", CEIL + "balanced_room_accuracy", "balanced: MCL ceiling", ".3f"),
    ("broom.blind", CEIL + "no_odometry.balanced_room_accuracy", "balanced: MCL, no odo.", ".3f"),
    ("broom.of_ceiling", None, "balanced: map, of the ceiling", ".2f"),
    ("pos.map", "localisation.position_error.map", "position error: map", ".2f"),
    ("pos.cells", "localisation.position_error.cells", "position error: cells", ".2f"),
    ("pos.chance", "localisation.position_error.chance", "position error: chance", ".2f"),
    ("pos.ceiling", CEIL + "position_error", "position error: MCL ceiling", ".2f"),
    ("ari.map", "rooms.adjusted_rand", "adjusted Rand: map communities", ".3f"),
    ("ari.cells", "rooms.adjusted_rand_cells", "adjusted Rand: cell communities", ".3f"),
    ("plan.map", "planning.success.map", "planning success: map", ".2f"),
    ("plan.random", "planning.success.random", "planning success: random", ".2f"),
    ("plan.ceiling", "ceiling.planning.success", "planning success: true-pose ceiling", ".2f"),
    ("plan.of_ceiling", None, "planning success: map, of the ceiling", ".2f"),
    ("states", "states.active", "active states", ".0f"),
)
# the map's number as a share of its ceiling (each seed's ratio, then the mean over seeds)
OF_CEILING = {
    "broom.of_ceiling": ("broom.map", "broom.ceiling"),
    "plan.of_ceiling": ("plan.map", "plan.ceiling"),
}
# claim -> (what, better, worse, minimum effect): holds if mean(better - worse) > margin, and
# > 2 standard errors over seeds with two seeds or more
CLAIMS = {
    "predicts": ("the map predicts the next cell better than Markov", "bits.markov", "bits.map"),
    "localises": ("the map localises the room better than its cells", "broom.map", "broom.cells"),
    "plans": ("the planner beats the random behaviour", "plan.map", "plan.random"),
}
FIGURES = ("place_fields.png", "map_graph.png")  # shown for each world's first seed
MARGINS = {"predicts": 0.05, "localises": 0.02, "plans": 0.05}  # bits/step; accuracy; rate


def _map_job(run: str, data: str, out: str, seed: int, pairs: int, key: str) -> dict:
    """One map (a worker's job): ``map_files`` into ``out``, then its cache key."""
    from sensorimotor.analysis.map.mapping import map_files

    res = map_files(run, data, out, seed=seed, pairs=pairs)
    write_json_atomic(Path(out) / "stage.json", {"key": key})
    return res.metrics


def targets(rep) -> list[tuple[str, str, str, str, int]]:
    """(world, model, name, run: "raw" or a run folder, seed) of every map, in report order."""
    out = []
    for world in rep.worlds:
        for seed in range(rep.seeds):
            out.append((world, "raw", f"raw__{world}__s{seed}", "raw", seed))
        for w, model, seed in rep.runs:
            if w == world:
                run = rep.run_dir(w, model, seed)
                out.append((world, model, run.name, str(run), seed))
    return out


def _settings(rep) -> dict:
    from sensorimotor.analysis.clusters import N_CLUSTERS
    from sensorimotor.analysis.map.chmm import EM_ITERS
    from sensorimotor.analysis.map.context import CONTEXT_TAU, N_CONTEXTS
    from sensorimotor.analysis.map.mapping import N_CLONES
    from sensorimotor.analysis.map.planning import BUDGET, N_PAIRS

    pairs = PAIRS.get(getattr(rep.scale, "name", ""), N_PAIRS)
    settings = {"clusters": N_CLUSTERS, "clones": N_CLONES, "em_iters": EM_ITERS}
    settings |= {"contexts": N_CONTEXTS, "context_tau": CONTEXT_TAU}
    return settings | {"pairs": pairs, "budget": BUDGET}


def jobs_of(rep, folder: Path) -> tuple[list[Job], list[tuple]]:
    """The jobs of the maps not kept under ``folder`` and every map's (world, model, name,
    seed, folder)."""
    settings = _settings(rep)
    data_hash = {w: file_hash(rep.data[w]) for w in rep.worlds}
    jobs, maps = [], []
    for world, model, name, run, seed in targets(rep):
        dest = folder / name
        model_hash = "raw" if run == "raw" else file_hash(Path(run) / "model.pt")
        key = stage_key(
            {
                "model": model_hash,
                "data": data_hash[world],
                "seed": seed,
                "settings": settings,
                "version": __version__,
                "stage": STAGE_VERSION,
            }
        )
        maps.append((world, model, name, seed, dest))
        if (dest / "map.json").exists() and read_key(dest / "stage.json") == key:
            continue
        args = (run, str(rep.data[world]), str(dest), seed, settings["pairs"], key)
        jobs.append(Job(f"map {name}", _map_job, args))
    return jobs, maps


def _get(metrics: dict, path: str):
    for part in path.split("."):
        if not isinstance(metrics, dict) or part not in metrics:
            return None
        metrics = metrics[part]
    return metrics


def _ratio(a, b):
    """a / b, None where either is missing or b is 0."""
    return None if a is None or not b else a / b


def _stats(values: list) -> dict:
    """mean, sd, n (``stats.describe``: sd 0.0 for one value) and the values; mean and sd None
    if any is None."""
    if not values or any(v is None for v in values):
        return {"mean": None, "sd": None, "n": len(values), "values": values}
    return {**describe(values), "values": [float(v) for v in values]}


WHERE = "experiments/map.py, MARGINS, commit cf27762, before docs/results/map"
TEST = (
    "mean of the paired per-seed differences above the margin and, with two seeds or more, "
    "above 2 standard errors over seeds (sd / sqrt(n))"
)
BINOMIAL = (
    "; the standard error at least the binomial one of the success rates' pairs, also with "
    "one seed (since 89d4108, after docs/results/map's first maps)"
)


# claim -> (provenance, how the settings it rests on were chosen): every margin was set before
# the data (WHERE); the settings of the map and of the test were not all
PROVENANCE = {
    "predicts": (BEFORE, "the map's settings (20 cells x 20 clones, EM, Viterbi) from issue 22"),
    "localises": (
        CHOSEN,
        "the context split and its 400-step history designed on the test split of Rec-SM "
        "seeds 0-1 (docs/results/map/diagnosis/split.py); its number of contexts, 4 there, "
        "chosen again on the validation split (raw and Rec-SM seed 0, Rooms1, 200,000 training "
        "steps, docs/results/map/diagnosis/select_contexts.py): 2",
    ),
    "plans": (
        CHOSEN,
        "300 pairs chosen after the 100-pair verdicts of these maps; a confirmatory test on "
        "300 fresh pairs, its rule written first, held (docs/results/map/diagnosis/confirm.py)",
    ),
}


def verdict(
    better: list,
    worse: list,
    margin: float,
    trials: list | None = None,
    claim: str = "",
    provenance: str = BEFORE,
    settings: str = "",
) -> Verdict:
    """The claim ``better - worse`` (``stats.paired_differences``, seed by seed) tested: its
    numbers (mean, sd, standard error, n, margin) and whether it holds (module docstring);
    ``holds`` None where a number is missing. ``trials``: each seed's number of trials when
    ``better`` and ``worse`` are success rates; the standard error is then at least the
    binomial one of the mean difference (so that one seed of 100 planning pairs is judged on
    its sampling error, about 0.07, too)."""
    numbers = {"mean": None, "sd": None, "se": None, "n": len(better), "margin": margin,
               "t_interval": None}  # fmt: skip
    holds = None
    if better and not any(v is None for v in [*better, *worse]):
        d = paired_differences(better, worse)
        mean, sd = mean_sd(d)
        se = standard_error(d)
        if trials is not None and all(t for t in trials):
            b, w = np.asarray(better, dtype=np.float64), np.asarray(worse, dtype=np.float64)
            var = (b * (1 - b) + w * (1 - w)) / np.asarray(trials, dtype=np.float64)
            binomial = float(math.sqrt(var.sum()) / len(d))
            se = binomial if se is None else max(se, binomial)
        holds = mean > margin and (se is None or mean > 2 * se)
        ci = t_interval(d)  # beside the verdict: its test is the margin and 2 SE
        numbers |= {"mean": mean, "sd": sd, "se": se, "t_interval": None if ci is None else list(ci)}
    return Verdict(
        claim=claim,
        threshold=f"mean paired difference above {margin:g}",
        test=TEST + (BINOMIAL if trials is not None else ""),
        numbers=numbers,
        holds=holds,
        provenance=provenance,
        where=WHERE + (f"; {settings}" if settings else ""),
    )


def aggregate(per_map: list[tuple[str, str, int, dict]]) -> dict:
    """{world: {model: {"seeds", "metrics": {key: stats}, "claims": {claim: verdict}}}} from
    (world, model, seed, map.json) of every map."""
    grouped: dict[str, dict[str, list]] = {}
    for world, model, seed, metrics in per_map:
        grouped.setdefault(world, {}).setdefault(model, []).append((seed, metrics))
    out: dict[str, dict] = {}
    for world, models in grouped.items():
        out[world] = {}
        for model in [m for m in with_raw() if m in models] + [m for m in models if m not in with_raw()]:
            maps = sorted(models[model], key=lambda sm: sm[0])
            values = {k: [_get(m, path) for _, m in maps] for k, path, _, _ in METRICS if path}
            for key, (num, den) in OF_CEILING.items():
                values[key] = [_ratio(a, b) for a, b in zip(values[num], values[den], strict=True)]
            pairs = [_get(m, "planning.pairs") for _, m in maps]
            out[world][model] = {
                "seeds": [s for s, _ in maps],
                "metrics": {key: _stats(v) for key, v in values.items()},
                "claims": {
                    c: verdict(
                        *(values[b], values[w], MARGINS[c], pairs if c == "plans" else None),
                        *(what, *PROVENANCE[c]),
                    ).to_dict()
                    for c, (what, b, w) in CLAIMS.items()
                },
            }
    return out


def run(ctx) -> dict:
    """Fit every map not kept (``ctx.run_jobs``); the numbers of all, aggregated over seeds."""
    rep = ctx.rep
    jobs, maps = jobs_of(rep, ctx.dir)
    ctx.log(f"  {len(jobs)} map(s) to fit, {len(maps) - len(jobs)} cached")
    ctx.run(jobs)
    per_map = []
    figures: dict[str, dict] = {}
    for world, model, _name, seed, dest in maps:
        per_map.append((world, model, seed, read_json(dest / "map.json", "map")))
        if seed == min(s for w, m, _, s, _ in maps if w == world and m == model):
            shown = {f: str((dest / f).relative_to(rep.out)) for f in FIGURES}
            figures.setdefault(world, {})[model] = shown
    return {
        "settings": _settings(rep),
        "margins": MARGINS,
        "jobs": {"fitted": len(jobs), "cached": len(maps) - len(jobs)},
        "worlds": aggregate(per_map),
        "figures": figures,
    }


def _cell(stats: dict, spec: str) -> str:
    if stats["mean"] is None:
        return "n/a"
    text = format(stats["mean"], spec)
    return f"{text} ± {format(stats['sd'], spec)}" if stats["n"] > 1 else text


def _claim_text(v: dict) -> str:
    """A claim's cell: its verdict word, the mean paired difference and its standard error."""
    if v["holds"] is None:
        return "n/a"
    n = v["numbers"]
    spread = "one seed" if n["se"] is None else f"SE {n['se']:.3f}"
    if n.get("t_interval"):
        spread += ", 95 % t [{:+.3f}, {:+.3f}]".format(*n["t_interval"])
    said = word(v["holds"], "**holds**", "does not hold")
    return f"{said}: {n['mean']:+.3f} ({spread}; {v.get('provenance', BEFORE)})"


def _provenance_text() -> str:
    """Where each claim's margin and settings come from (``PROVENANCE``)."""
    parts = [f"*{CLAIMS[c][0]}*: {prov}; {note}" for c, (prov, note) in PROVENANCE.items()]
    return "Provenance (every margin set before the data): " + "; ".join(parts) + "."


def section(rep, found: dict) -> list:
    """The map's report section: per world, the numbers side by side, the verdicts, figures."""
    s, m = found["settings"], found["margins"]
    b = [h(2, "From cells to a map (experiment `map`)")]
    b.append(
        p(
            f"The paper's proposed map, built: {s['clusters']} cells (k-means of each "
            f"representation), a cloned HMM of {s['clones']} clones per cell over cells and 4 "
            f"action bins (EM, at most {s['em_iters']} iterations, then Viterbi training), each "
            f"clone then split by {s['contexts']} slow contexts (k-means of the decayed history "
            f"of cells, {s['context_tau']:.0f} steps) and Viterbi-trained again, on "
            "each trained world's training split; numbers on its test split "
            "(`sensorimotor map`). Mean ± sd over seeds (raw: over the map's own seeds). "
            f"Planning: {s['pairs']} start/goal pairs, {s['budget']} steps each. A claim holds when the "
            "mean paired per-seed difference exceeds its margin "
            f"(bits/step {m['predicts']}, balanced room accuracy {m['localises']}, planning "
            f"success {m['plans']}) and, with two seeds or more, 2 standard errors over seeds "
            "(planning: 2 standard errors at least the binomial one of its pairs, also with one "
            "seed). "
            "Ceilings (`analysis/map/ceilings.py`): Monte-Carlo localisation on the known walls "
            "with the recorded odometry (and without: a random walk), and a planner with the "
            "true pose on the true walls, on the same start/goal pairs; the map's balanced room "
            "accuracy and planning success are also given as a share of them. Baselines: "
            "2nd- and 3rd-order (cell, action) models with back-off (chosen on validation), a "
            "GRU on (cell, action), and a class-balanced read-out of the decayed cell history. "
            f"{found['jobs']['fitted']} map(s) fitted this run, {found['jobs']['cached']} cached."
        )
    )
    for world, models in found["worlds"].items():
        names = list(models)
        b.append(h(3, f"The map on {world}"))
        header = ["", *(f"{short_name(n)} (n={len(models[n]['seeds'])})" for n in names)]
        rows = [
            [label, *(_cell(models[n]["metrics"][key], spec) for n in names)]
            for key, _, label, spec in METRICS
        ]
        b.append(table(header, rows))
        rows = [
            [what, *(_claim_text(models[n]["claims"][c]) for n in names)]
            for c, (what, _, _) in CLAIMS.items()
        ]
        b.append(table(["claim (paired difference)", *header[1:]], rows))
        b.append(p(_provenance_text()))
        shown = found["figures"].get(world, {})
        trained = [n for n in KINDS if n in shown]  # the last kind: Rec-SM if there
        pick = trained[-1] if trained else next(iter(shown), None)
        if pick is not None:
            for fig, caption in zip(
                FIGURES,
                ("place fields of the map's states", "the map's graph at its states' positions"),
                strict=True,
            ):
                path = Path(rep.out) / shown[pick][fig]
                if path.exists():
                    b.append(image(path, f"{short_name(pick)} on {world}: {caption}"))
    return b
