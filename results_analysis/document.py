"""A tiny document model rendered both as Markdown and as one self-contained HTML file.

The report is built once as a list of blocks (headings, paragraphs, tables, figures) and rendered twice,
so the Markdown and the HTML always say the same thing. The HTML embeds figures as base64 PNG and has
no external resources.
"""
from __future__ import annotations

import base64
import html
import re
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

_CSS = """
body{font-family:-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;max-width:60rem;margin:2rem auto;
padding:0 1rem;color:#1a1a1a;line-height:1.5}
h1{font-size:1.6rem;border-bottom:2px solid #0072B2;padding-bottom:.3rem}
h2{font-size:1.25rem;margin-top:2rem;border-bottom:1px solid #ddd}h3{font-size:1.05rem}
table{border-collapse:collapse;margin:.6rem 0 1.2rem;font-size:.85rem}
th,td{padding:.25rem .6rem;border-bottom:1px solid #e3e3e3;text-align:right}
th{border-bottom:2px solid #999;background:#f7f7f7}td:first-child,th:first-child{text-align:left}
caption{caption-side:top;text-align:left;font-weight:600;padding-bottom:.3rem}
figure{margin:1rem 0 1.6rem}figure img{max-width:100%}figcaption{font-size:.85rem;color:#444}
code{background:#f3f3f3;padding:0 .2rem}.note{color:#8a4b00}
"""


@dataclass
class Document:
    """Blocks of a report: ``("h", level, text)``, ``("p", text)``, ``("table", df, caption)``,
    ``("fig", name, caption)``, ``("list", items)``. Inline ``**bold**`` and ``*italic*`` are understood."""

    title: str
    blocks: list[tuple] = field(default_factory=list)

    def h(self, level: int, text: str) -> None:
        self.blocks.append(("h", level, text))

    def p(self, text: str) -> None:
        self.blocks.append(("p", text))

    def items(self, items: list[str]) -> None:
        self.blocks.append(("list", items))

    def table(self, df: pd.DataFrame, caption: str = "") -> None:
        self.blocks.append(("table", df, caption))

    def figure(self, name: str, caption: str) -> None:
        self.blocks.append(("fig", name, caption))

    def to_markdown(self, figure_dir: str = "figures") -> str:
        out = [f"# {self.title}", ""]
        for b in self.blocks:
            if b[0] == "h":
                out += ["#" * (b[1] + 1) + " " + b[2], ""]
            elif b[0] == "p":
                out += [b[1], ""]
            elif b[0] == "list":
                out += [f"- {i}" for i in b[1]] + [""]
            elif b[0] == "table":
                if b[2]:
                    out += [f"*{b[2]}*", ""]
                out += [_md_table(b[1]), ""]
            elif b[0] == "fig":
                out += [f"![{b[2]}]({figure_dir}/{b[1]}.png)", "", f"*{b[2]}*", ""]
        return "\n".join(out)

    def to_html(self, figure_dir: Path) -> str:
        body = [f"<h1>{_inline(self.title)}</h1>"]
        for b in self.blocks:
            if b[0] == "h":
                body.append(f"<h{b[1] + 1}>{_inline(b[2])}</h{b[1] + 1}>")
            elif b[0] == "p":
                body.append(f"<p>{_inline(b[1])}</p>")
            elif b[0] == "list":
                body.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in b[1]) + "</ul>")
            elif b[0] == "table":
                body.append(_html_table(b[1], b[2]))
            elif b[0] == "fig":
                data = base64.b64encode((figure_dir / f"{b[1]}.png").read_bytes()).decode("ascii")
                body.append(f'<figure><img alt="{html.escape(b[2])}" src="data:image/png;base64,{data}">'
                            f"<figcaption>{_inline(b[2])}</figcaption></figure>")
        return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>\n"
                + "\n".join(body) + "\n</body></html>\n")


def _inline(text: str) -> str:
    t = html.escape(text)
    t = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", t)
    t = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", t)
    t = re.sub(r"`(.+?)`", r"<code>\1</code>", t)
    return t


def _cells(df: pd.DataFrame) -> list[list[str]]:
    return [[_fmt(v) for v in row] for row in df.itertuples(index=False)]


def _fmt(v) -> str:
    if isinstance(v, (bool,)):
        return "yes" if v else "no"
    if isinstance(v, float):
        if v != v:
            return "–"
        return f"{v:.3f}" if abs(v) < 1000 else f"{v:.1f}"
    return str(v)


def _md_table(df: pd.DataFrame) -> str:
    head = "| " + " | ".join(map(str, df.columns)) + " |"
    sep = "|" + "|".join(["---"] + ["---:"] * (len(df.columns) - 1)) + "|"
    rows = ["| " + " | ".join(c.replace("|", "\\|") for c in r) + " |" for r in _cells(df)]
    return "\n".join([head, sep] + rows)


def _html_table(df: pd.DataFrame, caption: str) -> str:
    cap = f"<caption>{_inline(caption)}</caption>" if caption else ""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    rows = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in _cells(df))
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"
