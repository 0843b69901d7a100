"""Shared plumbing of the benchmarks: arguments, the data folder, markdown tables and JSON output."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]


def data_root() -> Path:
    """NEOSLAM_DATA, default ../shared/data beside the repository."""
    return Path(os.environ.get("NEOSLAM_DATA", REPO_ROOT.parent / "shared" / "data")).resolve()


def parse_args(description: str, extra=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true", help="fewer runs, for a smoke test")
    parser.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    if extra is not None:
        extra(parser)
    return parser.parse_args()


def markdown_table(rows: list[dict[str, Any]], columns: list[str]) -> str:
    def cell(value: Any) -> str:
        return f"{value:.3f}" if isinstance(value, float) else str(value)

    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cell(row.get(c, "")) for c in columns) + " |" for row in rows]
    return "\n".join(lines)


def write_json(path: Path | None, payload: dict[str, Any]) -> None:
    if path is not None:
        path.write_text(json.dumps(payload, indent=2) + "\n")
