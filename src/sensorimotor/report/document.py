"""The reproduction's report: one Markdown file and one self-contained HTML file.

The report is a list of blocks (headings, paragraphs, tables, images) rendered twice, so the two
files always say the same thing. Every number in it is read from the stages' outputs. It leads
with its verdicts: a summary (the claims, Table I against the paper), the contents, then the
numbers, the figures (the long grids folded), and the settings and timings last. The HTML embeds
its images downscaled (``MAX_IMAGE_WIDTH``, a palette of ``IMAGE_COLOURS``), so that a
reproduction's report stays a few megabytes.
"""

from __future__ import annotations

import base64
import html
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sensorimotor.analysis.analyze import RAW, with_raw
from sensorimotor.analysis.claims import claim_numbers, cluster_f1, fmt_ms, paper_claims
from sensorimotor.analysis.tables import PAPER_TABLE_I, fmt_cell
from sensorimotor.files import read_json, write_json_atomic, write_text_atomic
from sensorimotor.learn.evaluate import baseline_warnings
from sensorimotor.learn.models import KINDS, REC_SM, paper_panels


def label(name: str) -> str:
    """A representation's name in titles: the raw readings or a kind's label."""
    return "Sensory (raw readings)" if name == RAW else KINDS[name].label


MAX_IMAGE_WIDTH = 1100  # pixels of an image embedded in the HTML: the page's width
IMAGE_COLOURS = 128  # the embedded PNG's palette: plots and arrows need no more
VERDICT_CLASS = {
    "supported": "yes",
    "holds": "yes",
    "not supported": "no",
    "fails": "no",
    "not supported; needs --scale paper": "later",
    "n/a; needs --scale paper": "later",
}


@dataclass(frozen=True)
class Block:
    kind: str  # "h1" | "h2" | "h3" | "p" | "table" | "image" | "code" | "toc"
    content: object


def h(level: int, text: str) -> Block:
    return Block(f"h{level}", text)


def p(text: str) -> Block:
    return Block("p", text)


def table(header: list[str], rows: list[list[str]]) -> Block:
    return Block("table", (header, rows))


def image(path: Path, caption: str, folded: bool = False) -> Block:
    """A figure; ``folded``: one of a long grid, closed in the HTML until clicked."""
    return Block("image", (path, caption, folded))


def contents() -> Block:
    """The list of the report's sections (its level-2 headings), with links."""
    return Block("toc", None)


def anchor(text: str) -> str:
    """A heading's anchor, as GitHub makes it: lower case, punctuation dropped, spaces to -."""
    return re.sub(r"[^\w\- ]", "", text.lower()).replace(" ", "-")


def _sections(blocks: list[Block]) -> list[str]:
    return [str(b.content) for b in blocks if b.kind == "h2"]


def to_markdown(blocks: list[Block], root: Path) -> str:
    out = []
    for b in blocks:
        if b.kind == "toc":
            out.append("\n".join(f"- [{t}](#{anchor(t)})" for t in _sections(blocks)))
        elif b.kind.startswith("h"):
            out.append("#" * int(b.kind[1]) + " " + str(b.content))
        elif b.kind == "p":
            out.append(str(b.content))
        elif b.kind == "code":
            out.append(f"```\n{b.content}\n```")
        elif b.kind == "table":
            header, rows = b.content
            out.append("| " + " | ".join(header) + " |")
            out[-1] += "\n|" + "|".join("---" for _ in header) + "|"
            for row in rows:
                out[-1] += "\n| " + " | ".join(row) + " |"
        elif b.kind == "image":
            path, caption, _ = b.content
            out.append(f"![{caption}]({path.relative_to(root).as_posix()})\n\n*{caption}*")
    return "\n\n".join(out) + "\n"


def _inline_md(text: str) -> str:
    """Escape, then the bits of Markdown the report uses inline: **bold**, *italics*, `code`."""
    import re

    text = html.escape(text)
    text = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", text)
    text = re.sub(r"\*(.+?)\*", r"<i>\1</i>", text)
    return re.sub(r"`(.+?)`", r"<code>\1</code>", text)


def embedded_png(path: Path) -> bytes:
    """``path``'s image at most ``MAX_IMAGE_WIDTH`` wide, as a palette PNG: what the HTML
    embeds (the files on disk keep their full resolution)."""
    from PIL import Image

    with Image.open(path) as im:
        im = im.convert("RGB")
        if im.width > MAX_IMAGE_WIDTH:
            height = round(im.height * MAX_IMAGE_WIDTH / im.width)
            im = im.resize((MAX_IMAGE_WIDTH, height), Image.Resampling.LANCZOS)
        buf = io.BytesIO()
        im.quantize(IMAGE_COLOURS).save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def _cell(text: str, tag: str) -> str:
    verdict = VERDICT_CLASS.get(text)
    attr = f' class="{verdict}"' if verdict else ""
    return f"<{tag}{attr}>{_inline_md(text)}</{tag}>"


def to_html(blocks: list[Block], title: str) -> str:
    body = []
    for b in blocks:
        if b.kind == "toc":
            items = "".join(
                f'<li><a href="#{anchor(t)}">{html.escape(t)}</a></li>' for t in _sections(blocks)
            )
            body.append(f'<nav><ul class="toc">{items}</ul></nav>')
        elif b.kind.startswith("h"):
            text = str(b.content)
            body.append(f'<{b.kind} id="{anchor(text)}">{html.escape(text)}</{b.kind}>')
        elif b.kind == "p":
            body.append(f"<p>{_inline_md(str(b.content))}</p>")
        elif b.kind == "code":
            body.append(f"<pre>{html.escape(str(b.content))}</pre>")
        elif b.kind == "table":
            header, rows = b.content
            head = "".join(_cell(c, "th") for c in header)
            trs = "".join("<tr>" + "".join(_cell(c, "td") for c in r) + "</tr>" for r in rows)
            body.append(f"<table><thead><tr>{head}</tr></thead><tbody>{trs}</tbody></table>")
        elif b.kind == "image":
            path, caption, folded = b.content
            data = base64.b64encode(embedded_png(Path(path))).decode()
            figure = (
                f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(caption)}">'
                f"<figcaption>{html.escape(caption)}</figcaption></figure>"
            )
            if folded:
                figure = f"<details><summary>{html.escape(caption)}</summary>{figure}</details>"
            body.append(figure)
    style = (
        "body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;"
        "color:#222}table{border-collapse:collapse;margin:1em 0;font-size:0.9em}"
        "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f4f4f4}"
        "td:first-child,th:first-child{text-align:left}img{max-width:100%}"
        "figure{margin:1em 0}figcaption{font-style:italic;color:#555}"
        "pre{background:#f6f6f6;padding:0.8em;overflow-x:auto}"
        "td.yes,td.no,td.later{white-space:nowrap;text-align:center}td.later{color:#7a5a00;"
        "background:#fbf3d9}"
        "td.yes{background:#dff3df;color:#135e13}td.no{background:#f8dede;color:#8a1414}"
        "details{margin:0.4em 0}summary{cursor:pointer;color:#235}ul.toc{columns:2}"
    )
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{style}</style></head><body>{''.join(body)}</body></html>\n"
    )


# --- numbers -----------------------------------------------------------------------------------


def paper_agreement(rows: list[dict], worlds: list[str], tolerance: float = 0.25) -> str:
    """A sentence: how many Square-trained cells lie within ``tolerance`` of the paper's."""
    inside, outside = [], []
    for row in rows:
        for w in worlds:
            paper = PAPER_TABLE_I.get(row["model"], {}).get(w)
            if paper is None or w not in row["cells"]:
                continue
            ratio = row["cells"][w]["mean"] / paper - 1
            (inside if abs(ratio) <= tolerance else outside).append(
                f"{row['name']} on {w} ({ratio:+.0%})"
            )
    text = (
        f"Cells within {tolerance:.0%} of the paper: {len(inside)} of {len(inside) + len(outside)}"
    )
    return text + (f"; outside: {', '.join(outside)}." if outside else ".")


# --- figures -------------------------------------------------------------------------------------


def _figures(rep) -> dict[str, Path]:
    from sensorimotor.analysis.plots import plot_pca
    from sensorimotor.sim.database import load_database
    from sensorimotor.sim.figures import perception_figure, trajectories_figure, worlds_figure
    from sensorimotor.sim.plots import save_figure

    figs: dict[str, Path] = {}
    folder = rep.out / "figures"
    dbs = {w: load_database(p) for w, p in rep.data.items()}
    figs["worlds"] = save_figure(
        worlds_figure([db.world for db in dbs.values()]), folder / "worlds.png"
    )[0]
    figs["trajectories"] = save_figure(
        trajectories_figure(list(dbs.values())), folder / "trajectories.png"
    )[0]
    situation_db = dbs.get("rooms1", next(iter(dbs.values())))
    figs["perception"] = save_figure(perception_figure(situation_db), folder / "perception.png")[0]

    from matplotlib.figure import Figure

    for world in rep.worlds:
        panels = [("raw", rep.out / "analysis" / f"raw__{world}")] + [
            (k, rep.out / "analysis" / f"{world}__{k}__s0") for k in paper_panels()
        ]
        fig = Figure(figsize=(3.2 * len(panels), 3.2), layout="constrained")
        axes = fig.subplots(1, len(panels))
        for ax, (kind, folder_k) in zip(axes, panels, strict=True):
            with np.load(folder_k / "pca.npz", allow_pickle=False) as z:
                plot_pca(
                    z["pc"], z["min_reading"], ax=ax, title=label(kind), colorbar=ax is axes[-1]
                )
        figs[f"pca_{world}"] = save_figure(fig, folder / f"pca_{world}.png")[0]
    return figs


def _title(argv: list[str]) -> list[Block]:
    """The title and the command that made the report."""
    return [
        h(1, "sensorimotor: reproduction report"),
        p(
            "Kulak & Garcia Ortiz, *Representation Learning in Partially Observable Environments "
            "using Sensorimotor Prediction*: databases, the four encoders, Table I and the analysis "
            "of the representations, regenerated by one command."
        ),
        Block("code", " ".join(["sensorimotor", *argv[1:]]) if argv else "sensorimotor reproduce"),
    ]


def _summary(rep, verdicts: list) -> list[Block]:
    """What the reproduction found, first: the scale's caveat, each claim's verdict, and Table I
    (trained on Square) beside the paper's."""
    b = [h(2, "Summary")]
    if rep.scale.caveat:
        b.append(p(f"**Note.** {rep.scale.caveat}"))
    beyond = [v for v in verdicts if v.holds is not True and needs_paper(rep.scale, v.claim)]
    if beyond:
        b.append(
            p(
                f"**Needs `--scale paper`.** {len(beyond)} of the claims below are beyond the "
                f"{rep.scale.name} scale (measured: its models are too little trained for them) "
                "and are not supported or not judged here; their rows say so."
            )
        )
    rows = [
        [v.claim, v.word() + ("; needs --scale paper" if v in beyond else "")] for v in verdicts
    ]
    b.append(table(["the paper's claim", "verdict"], rows))
    rows_t = rep.table["tables"].get("square")
    if rows_t:
        worlds = rep.table["worlds"]
        body = []
        for row in rows_t:
            cells = [row["name"]]
            for w in worlds:
                mean = row["cells"][w]["mean"]
                paper = PAPER_TABLE_I.get(row["model"], {}).get(w)
                versus = "" if paper is None else f" (paper {paper:g}, {mean / paper - 1:+.0%})"
                cells.append(f"{mean:.5f}{versus}")
            body.append(cells)
        b.append(p("Table I, trained on Square: test error, mean over seeds, against the paper's."))
        b.append(table(["model", *worlds], body))
        b.append(p(paper_agreement(rows_t, worlds)))
    return b


def needs_paper(scale, claim: str) -> bool:
    """Whether ``claim`` is one that ``scale`` is too small to support (``Scale.beyond``)."""
    return any(claim.startswith(start) for start in getattr(scale, "beyond", ()))


def _settings(rep, hardware: dict) -> list[Block]:
    """What the reproduction ran with."""
    b = [h(2, "How this report was made")]
    b.append(
        table(
            ["", ""],
            [
                ["scale", f"{rep.scale.name} ({rep.scale.steps:,} steps per world)"],
                ["seeds", f"{rep.seeds} (0..{rep.seeds - 1}) per model and training world"],
                [
                    "epoch caps / patience",
                    (
                        ", ".join(f"{k}: {v}" for k, v in rep.scale.max_epochs.items())
                        or "none (early stopping alone)"
                    )
                    + f" / {rep.scale.patience} epochs",
                ],
                ["device / workers", f"{rep.device} / {rep.workers}"],
                ["package", hardware["sensorimotor"]],
                [
                    "hardware",
                    f"{hardware['processor']}, {hardware['cpus']} CPUs"
                    + (f", {hardware['cuda']}" if hardware["cuda"] else ""),
                ],
                [
                    "software",
                    f"Python {hardware['python']}, torch {hardware['torch']}, {hardware['platform']}",
                ],
            ],
        )
    )
    return b


def _timings(rep, figure_seconds: float) -> list[Block]:
    """Wall time of each stage of this invocation."""
    b: list[Block] = []
    rows = []
    for stage, t in rep.timings.items():
        if stage == "total":
            continue
        extra = f"{t.get('jobs', 0)} run, {t.get('cached', 0)} cached" if "jobs" in t else ""
        if t.get("during_training"):
            extra = f"{t['during_training']} run during training, " + extra
        rows.append([stage, f"{t.get('seconds', 0.0):.1f}", extra])
    rows.append(["report", f"{figure_seconds:.1f}", "figures (writing the files not counted)"])
    total = rep.timings.get("total", {}).get("seconds", 0.0) + figure_seconds
    rows.append(["total", f"{total:.1f}", ""])
    b += [
        h(3, "Wall time of each stage (this invocation)"),
        p(
            "Each run is evaluated and analysed as soon as it is trained, in a worker that "
            "training leaves free: the train stage's time includes that work."
        ),
        table(["stage", "seconds", "jobs"], rows),
    ]
    return b


def _trainings(rep) -> list[Block]:
    """Each run's training: epochs, best epoch and error, why it stopped, seconds."""
    b: list[Block] = []
    rows = []
    total_train = 0.0
    for world, kind, seed in rep.runs:
        res = read_json(rep.run_dir(world, kind, seed) / "result.json", "run result")
        total_train += res["seconds"]
        rows.append(
            [
                rep.run_name(world, kind, seed),
                str(res["epochs"]),
                str(res["best_epoch"]),
                f"{res['best_val_error']:.5f}",
                res["stopped"],
                f"{res['seconds']:.0f}",
            ]
        )
    rows.append(["all runs", "", "", "", "", f"{total_train:.0f}"])
    b += [
        h(3, "Training of each run (when it was trained; one thread each)"),
        table(["run", "epochs", "best epoch", "best val error", "stopped by", "seconds"], rows),
    ]
    return b


def _simulator(figs: dict[str, Path]) -> list[Block]:
    """The paper's Figs. 1-3."""
    b: list[Block] = []
    b.append(h(2, "Worlds, behaviour and perception (paper Figs. 1-3)"))
    b.append(image(figs["worlds"], "The three worlds (Fig. 1)"))
    b.append(
        image(figs["trajectories"], "10,000 steps of the random wall-avoiding behaviour (Fig. 2)")
    )
    b.append(
        image(
            figs["perception"],
            "What the agent perceives in the five situations, picked from the Rooms1 database by pose (Fig. 3)",
        )
    )
    return b


def _table_one(rep) -> list[Block]:
    """Table I for each training world, the baselines, the ordering, the paper beside."""
    b: list[Block] = []
    b.append(h(2, "Table I: sensorimotor prediction error"))
    b.append(
        p(
            "Test-split error: per step the squared error summed over the 5 scaled sensors, averaged "
            "over steps (the paper's Eq. 1). Recurrent models run over the whole test split from a zero "
            "state. Mean ± sample sd over seeds; the paper's value (trained on Square) in brackets. "
            "Baselines: predict the train-split mean reading; copy the last reading."
        )
    )
    t = rep.table
    for trained_on, rows_t in t["tables"].items():
        header = ["model"] + [w for w in t["worlds"]]
        body = []
        for row in rows_t:
            cells = [row["name"]]
            for w in t["worlds"]:
                c = fmt_cell(row["cells"].get(w))
                paper = (
                    PAPER_TABLE_I.get(row["model"], {}).get(w) if trained_on == "square" else None
                )
                cells.append(c + (f" [{paper:g}]" if paper is not None else ""))
            body.append(cells)
        for name in ("mean", "copy_last"):
            body.append(
                [f"baseline: {name.replace('_', '-')}"]
                + [f"{t['baselines'][w][name]:.5f}" for w in t["worlds"]]
            )
        order = t["paper_ordering_holds"][trained_on]
        body.append(
            ["paper ordering holds"]
            + [
                "yes" if order[w] else ("no" if order[w] is not None else "n/a")
                for w in t["worlds"]
            ]
        )
        b += [h(3, f"Trained on {trained_on}"), table(header, body)]
        if trained_on == "square":
            b.append(p(paper_agreement(rows_t, t["worlds"])))
        for row in rows_t:
            errors = {w: c["mean"] for w, c in row["cells"].items()}
            for line in baseline_warnings(row["name"], errors, t["baselines"]):
                b.append(p(f"**Warning.** {line}."))
    return b


def _inside(rep, figs: dict[str, Path], numbers: dict, worlds: list[str]) -> list[Block]:
    """What the representations contain: event F1, memory, position, PCA (Figs. 4-9)."""
    b: list[Block] = []
    b.append(h(2, "Inside the representations (paper Figs. 4-9)"))
    b.append(
        p(
            "z_s of each model on its training world's test split. Events are computed from pose and "
            "walls: a corner or a free wall end inside the sensor fan within range 10 and in line of "
            "sight; nothing in view (all readings 10); the distance to the wall straight behind. "
            "Event F1: the best single k-means cluster (k = 20) as a detector of the event. Memory: "
            "clusters that are mostly 'nothing in view', and the R² of a ridge probe for the distance "
            "behind among 'nothing in view' steps (fit on one half, scored on the other). Position: R² "
            "of ridge probes for x, y, cos(heading); KNN-MSE of the normalised position among the 5 "
            "nearest neighbours in representation space (lower is better). Mean ± sd over seeds."
        )
    )
    for world in worlds:
        body = []
        for kind in with_raw():
            v = numbers[world][kind]
            body.append(
                [
                    label(kind),
                    fmt_ms(v["corner_f1"]),
                    fmt_ms(v["wall_end_f1"]),
                    fmt_ms(v["nothing_clusters"], 1),
                    fmt_ms(v["behind_r2"]),
                    fmt_ms(v["r2_x"]),
                    fmt_ms(v["r2_y"]),
                    fmt_ms(v["r2_cos"]),
                    fmt_ms(v["knn_mse"], 3),
                ]
            )
        b += [
            h(3, f"Trained and analysed on {world}"),
            table(
                [
                    "representation",
                    "corner F1",
                    "wall-end F1",
                    "nothing clusters",
                    "behind R²",
                    "x R²",
                    "y R²",
                    "cos R²",
                    "KNN-MSE",
                ],
                body,
            ),
            p(
                f"KNN-MSE of random pairs of steps (chance) on {world}: "
                f"{numbers[world]['raw']['knn_chance'][0]:.3f}. Identical "
                "representations (every 'nothing in view' step of the raw readings, S and SM) "
                "are tied neighbours; ties count as the mean over all ways to break them."
            ),
        ]
        b.append(
            image(
                figs[f"pca_{world}"],
                f"PCA of z_s on {world}, coloured by the smallest reading (Fig. 4; seed 0)",
            )
        )
    return b


def _maps(rep) -> list[Block]:
    """The cluster maps of seed 0, and the transfer of clusters between worlds."""
    b: list[Block] = []
    b.append(h(2, "Cluster maps (paper Figs. 5-9)"))
    b.append(
        p(
            "Seed 0; 500 steps of each of the 20 k-means clusters drawn as arrows at their true "
            "pose. A panel's title: `#c share% event precision% (lift x)`: cluster c holds share % "
            "of the test steps; of its steps, precision % see the event it is richest in (corner, "
            "wall end, nothing in view), lift times that event's rate over all steps."
        )
    )
    shown = [(kind, "square") for kind in with_raw()] + [(REC_SM, "rooms1"), (REC_SM, "rooms2")]
    for kind, world in shown:
        name = f"raw__{world}" if kind == RAW else f"{world}__{kind}__s0"
        path = rep.out / "analysis" / name / "clusters.png"
        if path.exists():
            caption = f"{label(kind)} trained on {world}: the 20 clusters"
            b.append(image(path, caption, folded=True))

    b.append(h(3, "Transfer: Rec-SM and its clusters fitted on one world, applied to another"))
    b.append(
        p(
            "For each event, the cluster that detects it best on the world the clusters were fitted "
            "on (its number and F1 there), and the F1 of that same cluster on the other world."
        )
    )
    body = []
    for m in rep.transfers.values():
        fit, applied = m["fit_analysis"], m["analysis"]
        cells = [f"{fit['world']} → {applied['world']}"]
        for e in ("corner", "wall_end", "nothing"):
            if e not in fit["events"] or fit["events"][e]["cluster"] is None:
                cells.append("–")
                continue
            c = fit["events"][e]["cluster"]
            there = cluster_f1(applied, c, e)
            there_text = "none there" if math.isnan(there) else f"{there:.2f}"
            cells.append(f"#{c}: {fit['events'][e]['f1']:.2f} → {there_text}")
        body.append(cells)
    b.append(table(["fitted → applied", "corner F1", "wall-end F1", "nothing F1"], body))
    for name in rep.transfers:
        path = rep.out / "transfer" / name / "clusters.png"
        caption = f"{name.replace('__', ' ')}: clusters fitted on the training world drawn on the other"
        b.append(image(path, caption, folded=True))
    return b


def _claims(table_one: dict, transfers: dict, numbers: dict) -> tuple[list[Block], list]:
    """The paper's claims, each with its numbers, verdict and where its threshold was set
    (from numbers only: Table I, the transfer analyses, the claim numbers)."""
    verdicts = paper_claims(table_one, transfers, numbers)
    b: list[Block] = [h(2, "The paper's claims, tested")]
    rows = [[v.claim, v.numbers, v.word(), f"{v.provenance}: {v.where}"] for v in verdicts]
    b.append(table(["claim", "numbers", "verdict", "threshold set"], rows))
    b.append(
        p(
            "'threshold set' says whether a claim's threshold was fixed before any reproduction's "
            "numbers were seen or chosen after them, and where. `claims.json` holds each "
            "verdict with its threshold and test."
        )
    )
    return b, [v.to_dict() for v in verdicts]


def write_report(
    rep, argv: list[str], hardware: dict, extra: list[Block] = ()
) -> tuple[Path, Path]:
    """Write ``report.md``, ``report.html`` and ``claims.json`` into ``rep.out``; ``extra``:
    the sections of the experiments past the paper, after the paper's claims."""
    import time

    t0 = time.perf_counter()
    figs = _figures(rep)
    figure_seconds = time.perf_counter() - t0
    out = rep.out
    worlds = list(rep.worlds)  # trained on; every model is tested on all of rep.data
    numbers = claim_numbers(rep.analyses, rep.runs, worlds)
    claims, verdicts = _claims(rep.table, rep.transfers, numbers)
    b = [
        *_title(argv),
        *_summary(rep, paper_claims(rep.table, rep.transfers, numbers)),
        contents(),
        *_table_one(rep),
        *_inside(rep, figs, numbers, worlds),
        *claims,
        *extra,
        *_simulator(figs),
        *_maps(rep),
        *_settings(rep, hardware),
        *_timings(rep, figure_seconds),
        *_trainings(rep),
    ]
    md = to_markdown(b, out)
    page = to_html(b, "sensorimotor reproduction report")
    write_text_atomic(out / "report.md", md)
    write_text_atomic(out / "report.html", page)
    write_json_atomic(out / "claims.json", {"numbers": numbers, "claims": verdicts})
    return out / "report.md", out / "report.html"
