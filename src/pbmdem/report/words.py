"""The report's words: Jinja2 templates (pbmdem/data/report_templates/*.j2) filled from a dict of the
run's numbers, strictly (docs/validation.md, "Report"). A paragraph template is folded into one
line (`fold`: every line break with its indentation becomes one space; ``{{ space }}`` is a space
that folding keeps); a document template (`render`) keeps its lines. Filters: ``fmt(spec)``,
``pct(spec)`` (a fraction in %), ``mm(decimals=2)`` ("1.23 mm"), ``mmv(spec)`` (a number in mm),
``codes``, ``fold``.
"""

from __future__ import annotations

import html
import re

import jinja2

from pbmdem.atomic import write_csv, write_text

from .display import MM, PERCENT, STYLE, missing, table_html

#: a space that `fold` keeps (a private-use character, not whitespace, stands in for it while folding)
_KEPT = "\ue000"


def fold(text: str) -> str:
    """Lines joined by one space (blank lines and indentation dropped); ``{{ space }}`` kept."""
    return re.sub(rf"\s*{_KEPT}", " ", re.sub(r"\s*\n\s*", " ", str(text)).strip())


def _fmt(value, spec: str = "g") -> str:
    return format(value, spec)


def _pct(fraction, spec: str = ".1f") -> str:
    return format(PERCENT * float(fraction), spec)


def _mmv(value, spec: str = ".2f") -> str:
    return format(MM * float(value), spec)


def _codes(items) -> str:
    return ", ".join(f"``{item}``" for item in items)


def mm(value, decimals: int = 2) -> str:
    """A size in m as "1.23 mm"; "n/a" when missing."""
    return "n/a" if missing(value) else f"{MM * float(value):.{decimals}f} mm"


ENV = jinja2.Environment(
    loader=jinja2.PackageLoader("pbmdem", "data/report_templates"),
    undefined=jinja2.StrictUndefined,
    autoescape=False,  # reStructuredText, not HTML
    keep_trailing_newline=False,
)
ENV.filters.update(fold=fold, fmt=_fmt, pct=_pct, mm=mm, mmv=_mmv, codes=_codes)
ENV.globals.update(space=_KEPT)
#: the environment of a document rendered line by line (a block tag takes no line of its own)
LINES = ENV.overlay(trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)


def render(name: str, **numbers) -> str:
    """The document template `name` (without .j2) filled from `numbers`, line by line."""
    return LINES.get_template(f"{name}.j2").render(**numbers)


def paragraph(name: str, **numbers) -> str:
    """The template `name` filled from `numbers` and folded into one line."""
    return fold(ENV.get_template(f"{name}.j2").render(**numbers))


def macro(template: str, name: str):
    """The macro `name` of the template `template` (without .j2), returning folded text."""
    found = getattr(ENV.get_template(f"{template}.j2").module, name)
    return lambda *args, **kwargs: fold(found(*args, **kwargs))


def write_titled_table(csv, html_path, frame, name: str, numbers: dict | None = None, caption=None, keys: int = 1):
    """A display table as CSV (the values) and as an HTML page (what Snakemake's report shows), with
    its title and caption from the template tables.j2 (`numbers` fill them; `caption`: written elsewhere)."""
    numbers = numbers or {}
    if caption is None:
        caption = macro("tables", "caption")(name, numbers)
    title = macro("tables", "title")(name, numbers)
    write_csv(csv, frame)
    body = f"<h2>{html.escape(title)}</h2>" + (f"<p>{html.escape(caption)}</p>" if caption else "")
    write_text(
        html_path,
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{STYLE}</style></head><body>{body}{table_html(frame, keys)}</body></html>\n",
    )
