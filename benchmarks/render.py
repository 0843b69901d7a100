"""Put the stored benchmark results into the documentation pages: every table between the marker lines

    <!-- results: NAME TABLE -->
    <!-- end results -->

of a page in docs/benchmarks/ is replaced by table TABLE of benchmarks/results/NAME.json, with a line saying which
run made it (command, date, commit, machine, load). Likewise every figure between

    <!-- figure: NAME FIGURE -->
    <!-- end figure -->

is drawn from the stored result NAME (benchmarks/_figures.py) into docs/benchmarks/figures/NAME-FIGURE.svg and shown
there. The prose around the markers is the page's own.

    python -m benchmarks.render            # rewrite the pages whose tables changed
    python -m benchmarks.render --check    # exit 1 if a page is not what its results give (nothing written)
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

from benchmarks._figures import FIGURES, svg_text
from benchmarks.harness import REPO_ROOT, RESULTS, markdown_table

PAGES = REPO_ROOT / "docs" / "benchmarks"
FIGURE_FOLDER = "figures"  # beside the pages
FIGURE_MARKER = re.compile(
    r"^<!-- figure: (?P<name>[\w-]+) (?P<figure>[\w-]+) -->\n(?P<body>.*?)^<!-- end figure -->$",
    re.MULTILINE | re.DOTALL,
)
MARKER = re.compile(
    r"^<!-- results: (?P<name>[\w-]+) (?P<table>[\w .-]+?) -->\n(?P<body>.*?)^<!-- end results -->$",
    re.MULTILINE | re.DOTALL,
)


def stamp_line(result: dict[str, Any]) -> str:
    """One line on the run that made a table: command, date, commit, machine, load, wall time."""
    git = result.get("git", {})
    commit = (git.get("commit") or "unknown")[:10] + (" (uncommitted changes)" if git.get("dirty") else "")
    machine = result.get("machine", {})
    load = result.get("load_average", {})
    start, end = load.get("start") or [None], load.get("end") or [None]
    minutes = (result.get("wall_s") or 0.0) / 60.0
    return (
        f"*Measured by `{result['command']}` on {result['started'][:16].replace('T', ' ')} UTC, commit {commit}; "
        f"{machine.get('cpu', '?')}, {machine.get('cores', '?')} cores, {machine.get('ram_gb', '?')} GB, "
        f"Python {machine.get('python', '?')}; load average {start[0]} at the start, {end[0]} at the end; "
        f"{minutes:.1f} min.*"
    )


def render_table(result: dict[str, Any], table: str) -> str:
    """The stamp line and the table of a stored result (its title, when it has one, as a line before it)."""
    tables = result.get("tables", {})
    if table not in tables:
        known = ", ".join(sorted(tables)) or "none"
        raise KeyError(f"{result.get('benchmark')}: no table {table!r} in the stored result (tables: {known})")
    entry = tables[table]
    title = (entry.get("title") or "").lstrip("# ").strip()
    lines = [stamp_line(result), ""]
    if title:
        lines += [title, ""]
    return "\n".join(lines) + "\n" + markdown_table(entry["rows"], entry["columns"]) + "\n"


def load_result(name: str, results: Path = RESULTS) -> dict[str, Any] | None:
    path = results / f"{name}.json"
    return json.loads(path.read_text()) if path.is_file() else None


def render_page(text: str, results: Path = RESULTS) -> str:
    """The page with every marked table filled in from the stored results."""
    cache: dict[str, dict[str, Any] | None] = {}

    def fill(match: re.Match[str]) -> str:
        name, table = match["name"], match["table"].strip()
        if name not in cache:
            cache[name] = load_result(name, results)
        result = cache[name]
        if result is None:
            body = f"*No stored result: run `python -m benchmarks.{name}`, then `python -m benchmarks.render`.*\n"
        else:
            body = render_table(result, table)
        return f"<!-- results: {name} {table} -->\n{body}<!-- end results -->"

    return MARKER.sub(fill, text)


def render_figures(text: str, results: Path = RESULTS) -> tuple[str, dict[str, str]]:
    """The page with every marked figure shown, and the figures' SVG files (name -> text) it shows."""
    drawn: dict[str, str] = {}

    def fill(match: re.Match[str]) -> str:
        name, figure = match["name"], match["figure"]
        if (name, figure) not in FIGURES:
            known = ", ".join(f"{n} {f}" for n, f in sorted(FIGURES)) or "none"
            raise KeyError(f"no figure {name} {figure} (figures: {known})")
        draw, caption = FIGURES[name, figure]
        result = load_result(name, results)
        if result is None:
            body = f"*No stored result: run `python -m benchmarks.{name}`, then `python -m benchmarks.render`.*\n"
        else:
            file = f"{name}-{figure}.svg"
            drawn[file] = svg_text(draw(result))
            body = f"![{caption}]({FIGURE_FOLDER}/{file})\n"
        return f"<!-- figure: {name} {figure} -->\n{body}<!-- end figure -->"

    return FIGURE_MARKER.sub(fill, text), drawn


def _stale_figures(folder: Path, drawn: dict[str, str], write: bool) -> list[Path]:
    """The figure files that differ from what was drawn (written when `write`)."""
    stale = []
    for file, svg in drawn.items():
        path = folder / file
        if not path.is_file() or path.read_text() != svg:
            stale.append(path)
            if write:
                folder.mkdir(exist_ok=True)
                path.write_text(svg)
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a page would change")
    parser.add_argument("--pages", type=Path, default=PAGES, help="the folder of the pages (docs/benchmarks)")
    parser.add_argument("--results", type=Path, default=RESULTS, help="the stored results (benchmarks/results)")
    args = parser.parse_args(argv)
    stale = []
    for page in sorted(args.pages.glob("*.md")):
        text = page.read_text()
        try:
            rendered, drawn = render_figures(render_page(text, args.results), args.results)
        except KeyError as error:
            print(f"{page}: {error.args[0]}", file=sys.stderr)
            return 2
        if rendered != text:
            stale.append(page)
            if not args.check:
                page.write_text(rendered)
        stale += _stale_figures(args.pages / FIGURE_FOLDER, drawn, write=not args.check)
    for page in stale:
        print(f"{'stale' if args.check else 'rendered'}: {page}")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
