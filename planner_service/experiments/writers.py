"""CSV and JSON files of an experiment (the only file I/O of the package besides plots)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any, Sequence


def write_csv(rows: Sequence[dict[str, Any]], path: Path) -> Path:
    """One row per point; the columns of the first row, in order. NaN (an interval of one
    seed) is written as an empty cell."""
    if not rows:
        raise ValueError(f"no rows to write to {path}")
    fields = list(rows[0])
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()})
    return path


def jsonable(obj: Any) -> Any:
    """``obj`` with NaN and infinities as None (JSON has neither) and tuples as lists."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return jsonable(obj.item())
    return obj


def write_json(obj: Any, path: Path) -> Path:
    with open(path, "w") as f:
        json.dump(jsonable(obj), f, indent=1, allow_nan=False)
        f.write("\n")
    return path


__all__ = ["jsonable", "write_csv", "write_json"]
