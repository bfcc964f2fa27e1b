"""Markdown tables of the claims checked in a directory of experiment summaries (the JSON
files the ``experiment`` command writes), for docs/EXPERIMENTS.md.

``python -m planner_service.experiments.report DIR [DIR ...]`` prints them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from .registry import EXPERIMENTS


def _num(v: float | None, digits: int = 3) -> str:
    return "n/a" if v is None else f"{v:.{digits}g}"


def check_line(c: dict[str, Any]) -> str:
    return (f"| {c['where']} | {c['quantity']} | {_num(c['mean'])} | [{_num(c['lo'])}, {_num(c['hi'])}] "
            f"| {c['verdict']} |")


def claims_markdown(directory: Path) -> str:
    """Every claim of every experiment summary in ``directory``, with its checks."""
    lines: list[str] = []
    for name in EXPERIMENTS:
        path = directory / f"{name}.json"
        if not path.exists():
            continue
        summary = json.loads(path.read_text())
        run = summary["run"]
        lines.append(f"### {name} ({summary['paper']}, preset {summary['preset']}, {len(summary['seeds'])} seeds, "
                     f"commit {run.get('commit', '')[:7]})")
        lines.append("")
        for claim in summary["claims"]:
            lines.append(f"**{claim['id']}** ({claim['source']}): {claim['claim']}. Verdict: **{claim['verdict']}**.")
            lines.append("")
            lines.append("| where | quantity | mean | 95% interval | verdict |")
            lines.append("|---|---|---|---|---|")
            lines += [check_line(c) for c in claim["checks"]]
            lines.append("")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    for d in argv:
        print(claims_markdown(Path(d)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
