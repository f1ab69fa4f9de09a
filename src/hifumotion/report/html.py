"""A small HTML writer for the run report: escaped text, tables, figures; no scripts, no network.

The page's style is inline and its pictures are PNG files beside it (relative links), so
the report folder opens in any browser, offline, and its pictures are files a user can
reuse. :func:`referenced_files` lists what a page links to (the tests check every one exists).
"""

from __future__ import annotations

import html
import re
from pathlib import Path

STYLE = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; max-width: 1100px; margin: 2em auto;
       padding: 0 1em; color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #c0392b; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: .8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
th { background: #f4f4f4; }
td:first-child, th:first-child { text-align: left; }
figure { margin: 1em 0; }
figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.9em; color: #555; }
.note { background: #fff8e1; border-left: 4px solid #f0b429; padding: .4em .8em; }
.good { color: #1e7e34; font-weight: bold; }
.bad { color: #b02a37; font-weight: bold; }
code, pre { background: #f6f8fa; padding: .1em .3em; }
pre { padding: .6em; overflow-x: auto; }
nav a { margin-right: 1em; }
"""


def esc(text) -> str:
    return html.escape(str(text))


def fmt(value, digits: int = 4) -> str:
    """A number for a table cell: ``—`` for missing, scientific for very large or small."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int,)):
        return str(value)
    try:
        v = float(value)
    except (TypeError, ValueError):
        return esc(value)
    if v != v or v in (float("inf"), float("-inf")):
        return "—"
    if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
        return f"{v:.{max(digits - 1, 1)}e}"
    return f"{v:.{digits}g}"


def table(headers, rows, caption: str | None = None) -> str:
    """An HTML table; cells are formatted with :func:`fmt` unless already strings."""
    head = "".join(f"<th>{esc(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{c if isinstance(c, str) else fmt(c)}</td>" for c in r) + "</tr>"
                   for r in rows)
    cap = f"<caption>{esc(caption)}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def figure(src: str, caption: str) -> str:
    return f'<figure><img src="{esc(src)}" alt="{esc(caption)}"><figcaption>{esc(caption)}</figcaption></figure>'


def paragraph(text: str, cls: str | None = None) -> str:
    return f'<p class="{cls}">{esc(text)}</p>' if cls else f"<p>{esc(text)}</p>"


def section(anchor: str, title: str, parts: list[str]) -> str:
    return f'<section id="{esc(anchor)}"><h2>{esc(title)}</h2>{"".join(parts)}</section>'


def page(title: str, intro: list[str], sections: list[tuple[str, str, list[str]]]) -> str:
    """A whole page: title, introduction, a table of contents, the sections ``(anchor, title, parts)``."""
    nav = "".join(f'<a href="#{esc(a)}">{esc(t)}</a>' for a, t, _ in sections)
    body = "".join(section(a, t, p) for a, t, p in sections)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{esc(title)}</title>'
            f"<style>{STYLE}</style></head><body><h1>{esc(title)}</h1>{''.join(intro)}<nav>{nav}</nav>{body}"
            "</body></html>\n")


_LINK = re.compile(r'(?:src|href)="([^"#][^"]*)"')


def referenced_files(html_text: str) -> list[str]:
    """Relative files a page links to (images and links; not anchors or web addresses)."""
    return [html.unescape(m) for m in _LINK.findall(html_text) if "://" not in m and not m.startswith("mailto:")]


def missing_files(path: str | Path) -> list[str]:
    """The files ``path`` links to that do not exist beside it."""
    p = Path(path)
    return [r for r in referenced_files(p.read_text(encoding="utf-8")) if not (p.parent / r).exists()]


__all__ = ["table", "figure", "paragraph", "section", "page", "fmt", "esc", "referenced_files", "missing_files"]
