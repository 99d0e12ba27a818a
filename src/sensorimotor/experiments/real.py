"""Real data through the whole pipeline: a real robot's laser log and a real campus map, both
MRPT datasets shipped with the package (``sim.mrpt.SENA_LOG``, ``sim.mrpt.CAMPUS_MAP``;
BSD-3-Clause, provenance in their ``README.md``).

As ``reproduce --experiment real``, into ``OUT/real/``, each output cached beside the hash of
its inputs:

- **the recording**: ``import-rawlog`` of the SENA robot's loop (``sena.npz``: the paper's five
  rays, a unit a metre, poses from odometry, walls unknown); the reproduction's Square-trained
  seed-0 encoder of each kind tested on its test split beside the two baselines
  (``eval/square__{kind}__s0__on__sena.json``), and ``analyze raw`` of it (``analysis/raw__sena``);
- **the campus**: ``world import`` of the campus grid (``campus.toml``; its free space opened
  to ``sim.rosmap.CLEARANCE``, so no pocket traps the behaviour), a database of the
  paper's behaviour in it (``data/campus.npz``, ``CAMPUS_STEPS`` by scale, seed 0), each kind
  trained on it with the reproduction's epoch caps and patience (``runs/campus__{kind}__s0``),
  tested on its test split and on the real recording (``eval/campus__{kind}__s0.json``), and
  analysed with the raw readings (``analysis/``). The campus has 19,948 walls: the analysis'
  event truth (corners and wall ends in view) is quadratic in the walls, so the campus is
  analysed with its walls withheld (``data/campus_walls_withheld.npz``, the same rows): the
  position probes and "nothing in view" stay, corners and wall ends are n/a;
- **figures** (``sim.figures``): the real path with its scans (``real_path.png``) and the campus
  with a simulated trajectory (``campus_trajectory.png``; a trap, if one is found, marked).

``check(rep)`` refuses a reproduction without ``square`` before the paper's stages start.
"""

from __future__ import annotations

import math
from pathlib import Path

from sensorimotor.errors import InputError
from sensorimotor.files import file_hash, read_json, write_json_atomic, write_text_atomic
from sensorimotor.jobs.cache import read_key, stage_key
from sensorimotor.jobs.workers import Job
from sensorimotor.learn.models import paper_kinds
from sensorimotor.learn.runs import run_name
from sensorimotor.pipeline.stages import (
    analysis_job,
    eval_job,
    run_matches,
    train_config,
    train_job,
)
from sensorimotor.report.document import Block, h, image, p, table
from sensorimotor.sim import mrpt
from sensorimotor.sim.rosmap import CLEARANCE
from sensorimotor.version import __version__

LOG, GRIDMAP = mrpt.SENA_LOG, mrpt.CAMPUS_MAP  # the shipped recording and campus grid
TRAINED_ON = "square"  # the Square-trained encoders of Table I meet the real scans
SEED = 0
CAMPUS_STEPS = {"smoke": 20_000, "quick": 200_000, "paper": 1_000_000}
"""Rows of the campus database by scale (an unknown scale: ``quick``'s)."""
FIGURE_STEPS = 100_000  # the campus figure's trajectory
TRAPPED_ROWS = 1_000  # a database ending in this many rows without moving: the agent is trapped
REAL, CAMPUS = "sena", "campus"


# --- jobs (top-level: they run in worker processes) ---------------------------------------------


def _import_job(log: str, path: str, key: str) -> str:
    from sensorimotor.sim.database import save_database
    from sensorimotor.sim.rawlog import import_rawlog

    save_database(import_rawlog(log), path)
    write_json_atomic(Path(path).with_suffix(".json"), {"key": key})
    return path


def _world_job(gridmap: str, path: str, key: str) -> str:
    from sensorimotor.sim.floorplan import world_toml
    from sensorimotor.sim.rosmap import import_mrpt_map

    world, comment = import_mrpt_map(gridmap)
    write_text_atomic(Path(path), world_toml(world, comment))
    write_json_atomic(Path(path).with_suffix(".json"), {"key": key})
    return path


def _data_job(world: str, steps: int, path: str, withheld: str, key: str) -> str:
    """The campus database, and the same rows with the walls withheld (for the analyses)."""
    from sensorimotor.sim.database import Database, generate, save_database
    from sensorimotor.sim.world import load_world

    db = generate(load_world(world), steps, seed=SEED)
    save_database(db, path)
    meta = {**db.meta, "world": {"name": db.meta["world"]["name"]}}
    save_database(Database(db.sensors, db.motors, db.poses, meta=meta), withheld)
    write_json_atomic(Path(path).with_suffix(".json"), {"key": key})
    return path


# --- the stages ---------------------------------------------------------------------------------


def _kept(path: Path, key: str, *more: Path) -> bool:
    return read_key(path.with_suffix(".json")) == key and all(p.exists() for p in (path, *more))


def _eval(run: Path, data: list[Path], out: Path, hashes: dict) -> Job | None:
    key = stage_key({"model": file_hash(run / "model.pt"), "data": [hashes[d] for d in data]})
    if read_key(out) == key:
        return None
    out.parent.mkdir(parents=True, exist_ok=True)
    return Job(out.stem, eval_job, (str(run), [str(d) for d in data], str(out), key))


def _analysis(run: str, data: Path, out: Path, hashes: dict) -> Job | None:
    from sensorimotor.analysis import METRICS_VERSION

    model = "raw" if run == "raw" else file_hash(Path(run) / "model.pt")
    key = stage_key(
        {"model": model, "data": hashes[data], "version": __version__, "metrics": METRICS_VERSION}
    )
    if (out / "metrics.json").exists() and read_key(out / "stage.json") == key:
        return None
    return Job(f"analysis {out.name}", analysis_job, (run, str(data), str(out), None, key))


def _run(jobs: list) -> list:
    return [job for job in jobs if job is not None]


def check(rep) -> None:
    """Refuse, before any stage, a reproduction that does not train on square (the recording
    meets the Square-trained encoders)."""
    if TRAINED_ON not in tuple(rep.worlds):
        raise InputError(
            "experiment real: needs the models trained on square; add square to --worlds"
        )


def run(ctx) -> dict:
    """Every stage (cached), the figures, and the numbers of the section."""
    rep = ctx.rep
    check(rep)
    d = ctx.dir
    scale = getattr(rep.scale, "name", "")
    steps = CAMPUS_STEPS.get(scale, CAMPUS_STEPS["quick"])
    kinds = paper_kinds()
    for sub in ("data", "eval", "analysis", "runs"):
        (d / sub).mkdir(parents=True, exist_ok=True)

    # 1. the recording and the campus world
    sena, world = d / f"{REAL}.npz", d / f"{CAMPUS}.toml"
    sena_key = stage_key({"log": file_hash(LOG), "version": __version__})
    world_key = stage_key(
        {"map": file_hash(GRIDMAP), "clearance": CLEARANCE, "version": __version__}
    )
    jobs = [
        None
        if _kept(sena, sena_key)
        else Job("import sena", _import_job, (str(LOG), str(sena), sena_key)),
        None
        if _kept(world, world_key)
        else Job("import campus", _world_job, (str(GRIDMAP), str(world), world_key)),
    ]
    ctx.run(_run(jobs))

    # 2. the campus database; the Square-trained encoders and the raw readings on the recording
    campus, withheld = d / "data" / f"{CAMPUS}.npz", d / "data" / f"{CAMPUS}_walls_withheld.npz"
    data_key = stage_key(
        {"world": file_hash(world), "steps": steps, "seed": SEED, "version": __version__}
    )
    hashes = {sena: file_hash(sena)}
    square = {k: rep.run_dir(TRAINED_ON, k, SEED) for k in kinds}
    on_real = {k: d / "eval" / f"{run_name(TRAINED_ON, k, SEED)}__on__{REAL}.json" for k in kinds}
    jobs = [
        None
        if _kept(campus, data_key, withheld)
        else Job(
            "campus data", _data_job, (str(world), steps, str(campus), str(withheld), data_key)
        ),
        *(_eval(Path(square[k]), [sena], on_real[k], hashes) for k in kinds),
        _analysis("raw", sena, d / "analysis" / f"raw__{REAL}", hashes),
    ]
    ctx.run(_run(jobs))

    # 3. each kind trained on the campus
    hashes |= {campus: file_hash(campus), withheld: file_hash(withheld)}
    device = getattr(rep, "device", "cpu")
    runs = {k: d / "runs" / run_name(CAMPUS, k, SEED) for k in kinds}
    jobs = []
    for k in kinds:
        config = train_config(k, device, rep.scale.epochs(k), rep.scale.patience)
        done = (runs[k] / "result.json").exists()
        if not (done and run_matches(runs[k], hashes[campus], {**config, "seed": SEED})):
            entry = (str(campus), SEED, str(runs[k]), hashes[campus])
            jobs.append(Job(f"train {runs[k].name}", train_job, ([entry], config)))
    ctx.run(jobs)

    # 4. tested on the campus and on the recording; analysed on the campus (walls withheld)
    evals = {k: d / "eval" / f"{runs[k].name}.json" for k in kinds}
    jobs = [_eval(runs[k], [campus, sena], evals[k], hashes) for k in kinds]
    jobs += [_analysis("raw", withheld, d / "analysis" / f"raw__{CAMPUS}", hashes)]
    jobs += [
        _analysis(str(runs[k]), withheld, d / "analysis" / runs[k].name, hashes) for k in kinds
    ]
    ctx.run(_run(jobs))

    figures = _figures(d, sena, world, campus, hashes)
    return _numbers(d, kinds, sena, world, campus, square, on_real, runs, evals, steps, figures)


def _figures(d: Path, sena: Path, world: Path, campus: Path, hashes: dict) -> dict[str, str]:
    """The two figures, drawn again only when their inputs changed."""
    from sensorimotor.sim.database import load_database
    from sensorimotor.sim.figures import campus_figure, real_path_figure
    from sensorimotor.sim.plots import save_figure
    from sensorimotor.sim.world import load_world

    names = {"real": "real_path.png", "campus": "campus_trajectory.png"}
    campus_db = load_database(campus)
    trapped = trapped_from(campus_db)
    key = stage_key(
        {
            "log": file_hash(LOG),
            "sena": hashes[sena],
            "world": file_hash(world),
            "campus": hashes[campus],
            "steps": FIGURE_STEPS,
            "trapped": trapped,
            "version": __version__,
        }
    )
    mark = d / "figures.json"
    if read_key(mark) != key or not all((d / n).exists() for n in names.values()):
        fig = real_path_figure(LOG, load_database(sena))
        save_figure(fig, d / names["real"], dpi=110)
        fig = campus_figure(load_world(world), campus_db, FIGURE_STEPS, trapped)
        save_figure(fig, d / names["campus"], dpi=110)
        write_json_atomic(mark, {"key": key})
    return names


# --- the numbers --------------------------------------------------------------------------------


def _num(x) -> float | None:
    """A strict-JSON number: None for a missing or non-finite one."""
    return float(x) if isinstance(x, int | float) and math.isfinite(x) else None


def _highlights(out: Path) -> dict:
    """What the section says of one analysis: its steps, the "nothing in view" detector, the
    position probes and the neighbours' position error against chance."""
    a = read_json(out / "metrics.json", "analysis")["analysis"]
    pos = a["position"]
    return {
        "steps": a["n_steps"],
        "walls_known": a.get("walls_known", True),
        "nothing_rate": _num(a["events"].get("nothing", {}).get("rate")),
        "nothing_f1": _num(a["events"].get("nothing", {}).get("f1")),
        "r2_x": _num(pos["r2_x"]),
        "r2_y": _num(pos["r2_y"]),
        "knn_mse": _num(pos["knn_mse"]),
        "knn_mse_chance": _num(pos["knn_mse_chance"]),
    }


def trapped_from(db) -> int | None:
    """The row from which the agent never moves again (``d`` 0 to the end), when that is
    ``TRAPPED_ROWS`` rows or more: the paper's behaviour turns around whenever a reading is
    under 1 unit, so a pocket of a real map where no heading clears all five rays traps it
    for good (the import's clearance opening closes such pockets: this checks that it did);
    None when it moves to near the end."""
    import numpy as np

    moved = np.nonzero(np.asarray(db.motors[:, 0]) > 0)[0]
    start = int(moved[-1]) + 1 if len(moved) else 0
    return start if len(db) - start >= TRAPPED_ROWS else None


def _one(res: dict, name: str) -> tuple[float | None, dict]:
    """A run's error on the database of world ``name`` and that database's baselines."""
    base = res["baselines"][name]
    return _num(res["errors"][name]), {k: _num(base[k]) for k in ("mean", "copy_last")}


def _numbers(d, kinds, sena, world, campus, square, on_real, runs, evals, steps, figures) -> dict:
    from sensorimotor.sim.database import load_database
    from sensorimotor.sim.world import load_world

    real_db, campus_db = load_database(sena), load_database(campus)
    real_name, campus_name = real_db.meta["world"]["name"], campus_db.meta["world"]["name"]
    src = real_db.meta["source"]
    real: dict = {"models": {}}
    for k in kinds:
        error, real["baselines"] = _one(read_json(on_real[k], "evaluation")["result"], real_name)
        trained = read_json(Path(square[k]) / "result.json", "run result")
        real["models"][k] = {
            "run": Path(square[k]).name,
            "error": error,
            "val_error_square": _num(trained.get("best_val_error")),
        }
    copy = real["baselines"]["copy_last"]
    real |= {
        "log": LOG.name,
        "name": real_name,
        "rows": len(real_db),
        "test_rows": len(real_db.take("test")),
        "scans": src["counts"]["scans"],
        "rate_hz": _num(src["rate_hz"]),
        "duration_s": _num(src["duration_s"]),
        "beams_invalid": src["counts"]["beams_invalid"],
        "beat_copy_last": [
            k
            for k, m in real["models"].items()
            if None not in (m["error"], copy) and m["error"] < copy
        ],
        "analysis_raw": _highlights(d / "analysis" / f"raw__{REAL}"),
    }
    w = load_world(world)
    camp: dict = {"models": {}}
    for k in kinds:
        res = read_json(evals[k], "evaluation")["result"]
        error, camp["baselines"] = _one(res, campus_name)
        trained = read_json(runs[k] / "result.json", "run result")
        camp["models"][k] = {
            "run": runs[k].name,
            "error": error,
            "on_real": _one(res, real_name)[0],
            "best_val_error": _num(trained.get("best_val_error")),
            "epochs": trained.get("epochs"),
            "stopped": trained.get("stopped"),
        }
    trapped = trapped_from(campus_db)
    camp |= {
        "trapped_from": trapped,
        "trapped_at": None
        if trapped is None
        else [_num(float(v)) for v in campus_db.poses[trapped, :2]],
        "beat_copy_last_on_real": [
            k
            for k, m in camp["models"].items()
            if None not in (m["on_real"], copy) and m["on_real"] < copy
        ],
        "map": GRIDMAP.name,
        "clearance": CLEARANCE,
        "world": w.name,
        "walls": len(w.walls),
        "size": [_num(w.width), _num(w.height)],
        "steps": steps,
        "test_rows": len(campus_db.take("test")),
        "analysis": {
            kind: _highlights(
                d / "analysis" / (f"raw__{CAMPUS}" if kind == "raw" else runs[kind].name)
            )
            for kind in ("raw", *kinds)
        },
    }
    return {"real": real, "campus": camp, "figures": figures}


# --- the section --------------------------------------------------------------------------------


def _f(x, digits: int = 4) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def _analysis_rows(analyses: dict) -> list[list[str]]:
    rows = []
    for kind, a in analyses.items():
        chance = _f(a["knn_mse_chance"], 3)
        rows.append(
            [
                kind,
                f"{a['steps']:,}",
                _f(a["nothing_f1"], 2),
                _f(a["r2_x"], 2),
                _f(a["r2_y"], 2),
                f"{_f(a['knn_mse'], 3)} ({chance})",
            ]
        )
    return rows


ANALYSIS_HEADER = [
    "representation",
    "test steps",
    "nothing-in-view F1",
    "x R²",
    "y R²",
    "KNN-MSE (chance)",
]


def section(rep, found: dict) -> list[Block]:
    """The recording through the Square-trained encoders, the campus trained on like the
    paper's worlds, their analyses and figures."""
    real, camp = found["real"], found["campus"]
    root = Path(rep.out) / "real"
    base = real["baselines"]
    rate = real["rate_hz"]
    b = [h(2, "Real data: a real robot's laser log and a real campus map")]
    b.append(
        p(
            f"Two MRPT datasets shipped with the package (BSD-3-Clause): `{real['log']}`, the SENA "
            f"robot driving one loop in a faculty building ({real['scans']} laser scans, "
            f"{real['rows']} rows at {_f(rate, 2)} Hz over {_f(real['duration_s'], 1)} s), and "
            f"`{camp['map']}`, an occupancy grid of a university campus. The recording is imported "
            "with the paper's five rays (-0.6 .. 0.6 rad, the nearest of the laser's beams), a unit "
            "a metre, readings beyond 10 m and invalid beams read 10, poses from odometry; its "
            "walls are unknown."
        )
    )
    b.append(
        image(
            root / found["figures"]["real"],
            "The real path with its scans (left) and "
            "the five kept readings along the recording (right)",
        )
    )
    b.append(h(3, "Square-trained encoders on the real scans"))
    rows = [
        [
            k,
            _f(m["error"]),
            _f(base["mean"]),
            _f(base["copy_last"]),
            "yes" if k in real["beat_copy_last"] else "no",
            _f(m["val_error_square"]),
        ]
        for k, m in real["models"].items()
    ]
    b.append(
        table(
            [
                "model",
                "error on the real scans",
                "mean baseline",
                "copy-last baseline",
                "beats copy-last?",
                "its validation error on Square",
            ],
            rows,
        )
    )
    beat_mean = [
        k
        for k, m in real["models"].items()
        if None not in (m["error"], base["mean"]) and m["error"] < base["mean"]
    ]
    mean_text = (
        "Every model beats the mean baseline"
        if len(beat_mean) == len(real["models"])
        else f"{len(beat_mean)} of {len(real['models'])} models beat the mean baseline"
    )
    if not real["beat_copy_last"]:
        copy_text = (
            "none beats copying the last reading: at "
            f"{_f(rate, 1)} Hz a real robot's readings change little from one row to the next, "
            "and encoders trained where a step moves up to one unit in a 50 x 50 box have never "
            "seen a corridor, clutter or the 10 m cap held for seconds"
        )
    else:
        copy_text = f"{', '.join(real['beat_copy_last'])} beat(s) copying the last reading"
    b.append(
        p(
            f"Error: the mean squared error of the predicted next reading on the recording's test "
            f"split (its last 10 %, **{real['test_rows']} rows**), as for the paper's worlds. "
            f"{mean_text}; {copy_text}. {real['test_rows']} test rows are few: these numbers say "
            "the pipeline runs on real data, not how well it transfers."
        )
    )
    a = real["analysis_raw"]
    b.append(
        p(
            f"`analyze raw` on the recording ({a['steps']} test steps, walls unknown: the corner, "
            f"wall-end and distance-behind analyses are n/a): nothing in view on "
            f"{_f(None if a['nothing_rate'] is None else 100 * a['nothing_rate'], 1)} % of steps "
            f"(best cluster's F1 {_f(a['nothing_f1'], 2)}); position from the readings R² x "
            f"{_f(a['r2_x'], 2)}, y {_f(a['r2_y'], 2)}; KNN-MSE {_f(a['knn_mse'], 3)} against "
            f"chance {_f(a['knn_mse_chance'], 3)}."
        )
    )

    b.append(h(3, "The campus world, trained on like the paper's worlds"))
    width, height = camp["size"]
    opened = (
        f", opened to a clearance of {camp['clearance']:g} m: narrower places, where the "
        "behaviour could walk into a pocket it cannot turn out of, are closed"
        if camp.get("clearance")
        else ""
    )
    b.append(
        p(
            f"`world import` of the grid gives `{camp['world']}`, {_f(width, 1)} x {_f(height, 1)} m "
            f"with {camp['walls']:,} walls (a cell is free when its occupancy is below 0.196; the "
            f"largest connected free region{opened}). A database of {camp['steps']:,} steps of "
            "the paper's behaviour in it (seed 0) trains each kind (seed 0, the reproduction's "
            f"epoch caps and patience); tested on its test split ({camp['test_rows']:,} rows) "
            "and, in metres like the campus, on the real recording's."
        )
    )
    if camp.get("trapped_from") is not None:
        n, (x, y) = camp["trapped_from"], camp["trapped_at"]
        test_start = camp["steps"] - camp["test_rows"]
        in_test = min(1.0, (camp["steps"] - max(n, test_start)) / camp["test_rows"])
        b.append(
            p(
                f"**The simulated agent was trapped**: from step {n:,} on it turns in place at "
                f"({_f(x, 1)}, {_f(y, 1)}) m, in a pocket of the real map where no heading clears "
                "all five rays (the paper's behaviour turns around whenever a reading is under 1 "
                f"unit). {100 * (camp['steps'] - n) / camp['steps']:.0f} % of the database and "
                f"{100 * in_test:.0f} % of its test split are that trap: the campus numbers below "
                "are not a fair test of the encoders."
            )
        )
    b.append(
        image(
            root / found["figures"]["campus"],
            "The campus's walls and a simulated trajectory in it (seed 0)",
        )
    )
    cb = camp["baselines"]
    rows = [
        [
            k,
            _f(m["error"]),
            _f(cb["mean"]),
            _f(cb["copy_last"]),
            _f(m["on_real"]),
            f"{m['epochs']} ({m['stopped']})",
        ]
        for k, m in camp["models"].items()
    ]
    b.append(
        table(
            [
                "model",
                "error in the campus",
                "mean baseline",
                "copy-last baseline",
                "error on the real scans",
                "epochs",
            ],
            rows,
        )
    )
    worse = [
        k
        for k, m in camp["models"].items()
        if None not in (m["error"], cb["copy_last"]) and m["error"] >= cb["copy_last"]
    ]
    if worse:
        b.append(p(f"Not better than copying the last reading in the campus: {', '.join(worse)}."))
    copy = base["copy_last"]
    better = camp["beat_copy_last_on_real"]
    if better:
        errors = ", ".join(f"{k} {_f(camp['models'][k]['on_real'])}" for k in better)
        b.append(
            p(
                f"On the real scans, trained in the campus (metres, a real site's layout), "
                f"{', '.join(better)} predict(s) better than copying the last reading ({errors} "
                f"against {_f(copy)}); on {real['test_rows']} test rows a gap this size says little."
            )
        )
    else:
        b.append(
            p(
                "On the real scans, none of the campus-trained models beats copying the last "
                f"reading ({_f(copy)}) either."
            )
        )
    b.append(
        p(
            "Analyses of the campus's test split. Its walls are withheld: the event truth (corners "
            f"and wall ends in view) is quadratic in the walls, too slow for {camp['walls']:,}, so "
            "corners and wall ends are n/a; the position probes and 'nothing in view' remain. "
            "KNN-MSE: the normalised position's error among the 5 nearest neighbours in "
            "representation space (lower is better)."
        )
    )
    b.append(table(ANALYSIS_HEADER, _analysis_rows(camp["analysis"])))
    return b
