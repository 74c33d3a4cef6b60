"""A sweep directory as the figures read it: its index table (``index.csv``) and ``sweep.json``.

The sweep runner (:mod:`gnerun.runs.sweep`) writes them; readers (``gnerun figures``) need nothing of the
runner, so the file names and the reader live here, with the sink.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..files import MAX_JSON_BYTES, read_regular

INDEX_CSV = "index.csv"
SWEEP_JSON = "sweep.json"
SEED_AXES = ("disturbance.seed", "disturbance.plant.seed")  # averaged over in the sweep figures


def read_index(sweep_dir: str | Path) -> list[dict[str, Any]]:
    """index.csv as rows of typed values (numbers as numbers, empty as None); a file that is not one (not text, not
    a regular file, too large) is an InputError that says it is damaged."""
    path = Path(sweep_dir) / INDEX_CSV
    if not path.exists():
        raise InputError(f"{sweep_dir}: no sweep index here (expected {INDEX_CSV})")
    data = read_regular(path, MAX_JSON_BYTES, INDEX_CSV)
    try:  # a row cut short has its missing cells empty; the cells of a row too long are left out
        return [{k: _parse_cell(v) for k, v in r.items() if k is not None}
                for r in csv.DictReader(io.StringIO(data.decode(), newline=""), restval="")]
    except (UnicodeDecodeError, csv.Error) as e:
        raise InputError(f"{path}: damaged {INDEX_CSV}: {str(e).splitlines()[0][:80]}") from None


def _parse_cell(text: str) -> Any:
    if text == "":
        return None
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    if text[:1] in "[{":
        try:
            return json.loads(text)
        except ValueError:
            pass
    return text


def is_sweep_dir(path: str | Path) -> bool:
    p = Path(path)
    return p.is_dir() and (p / INDEX_CSV).is_file() and (p / SWEEP_JSON).is_file()


def loglog_slope(x: list[float], y: list[float]) -> float | None:
    """Least-squares slope of log10 y against log10 x over the positive finite pairs."""
    pairs = [(a, b) for a, b in zip(x, y, strict=True) if a and b and a > 0 and b > 0
             and math.isfinite(a) and math.isfinite(b)]
    if len(pairs) < 2:
        return None
    lx, ly = np.log10([p[0] for p in pairs]), np.log10([p[1] for p in pairs])
    return float(np.polyfit(lx, ly, 1)[0])
