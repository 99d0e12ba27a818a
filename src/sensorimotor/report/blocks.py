"""The report's blocks (headings, paragraphs, tables, images, the contents) and their two
renderings: Markdown, and one self-contained HTML page whose images are embedded downscaled
(``MAX_IMAGE_WIDTH``, a palette of ``IMAGE_COLOURS``), so that a report stays a few megabytes.
The experiments build their sections from these blocks; ``document`` writes the report."""

from __future__ import annotations

import base64
import html
import io
import re
from dataclasses import dataclass
from pathlib import Path

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
