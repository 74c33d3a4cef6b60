"""Runtime parameters: inputs of the compiled functions, like the plant state, changed without recompiling.

A game's runtime values are one vector p, appended to the plant state wherever a compiled function takes the state
(``CompiledGame._x``). Its layout (:class:`RuntimeLayout`):

- in a dynamic game that uses the absolute time ``t``: p[0] = t_k, the time of the sampling time solved; stage tau
  sees t = t_k + tau * dt (dt the sampling time), the terminal cost t_k + (T + 1) * dt;
- then every runtime parameter in the order declared: a number (one entry), a vector (its entries), a matrix (row by
  row), a per-stage table or a data file's column (T + 2 entries: stages 0..T and the terminal cost's T + 1).

A data file's column is interpolated at the stages' times of every sampling time (:meth:`RuntimeLayout.vector`), so
the window moves with the closed loop. Values given at run time (the Python API's ``parameters`` callback, a sweep)
replace the declared ones, shape checked.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .expr import evaluate, numpy_functions, parse_expression

_TIME = re.compile(r"(?<![A-Za-z0-9_])t(?![A-Za-z0-9_])")


@dataclass(frozen=True)
class Table:
    """A data file's time column and one value column (both float64; times strictly increasing)."""

    times: np.ndarray
    values: np.ndarray
    interpolation: str  # linear | hold
    path: str

    def at(self, t: np.ndarray) -> np.ndarray:
        if self.interpolation == "hold":
            k = np.searchsorted(self.times, t, side="right") - 1
            return self.values[np.clip(k, 0, self.values.size - 1)]
        return np.interp(t, self.times, self.values)


@dataclass(frozen=True)
class Entry:
    """Where one runtime parameter sits in p."""

    name: str
    kind: str  # scalar | vector | matrix | stages
    shape: tuple[int, ...]
    start: int
    default: np.ndarray  # its declared value, flattened (per stage: T + 2 entries)
    table: Table | None = None

    @property
    def size(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1

    @property
    def slice(self) -> slice:
        return slice(self.start, self.start + self.size)


class SymbolTable:
    """A vector, matrix or per-stage runtime parameter as the expression evaluator indexes it (``env[name + '[]']``):
    vectors and matrices from 1, like the other parameters; per-stage tables from 0, like tau."""

    def __init__(self, entry: Entry, values: Any):
        self.entry, self.values = entry, values

    def at(self, indices: list[int]) -> Any:
        e = self.entry
        base = 0 if e.kind == "stages" else 1
        if len(indices) != len(e.shape):
            raise ValueError(f"{e.name!r} takes {len(e.shape)} ind{'ex' if len(e.shape) == 1 else 'ices'}, "
                             f"not {len(indices)}")
        flat = 0
        for k, n in zip(indices, e.shape, strict=True):
            if not base <= k < n + base:
                raise ValueError(f"index {k} of {e.name!r} is outside {base}..{n + base - 1}")
            flat = flat * n + (k - base)
        return self.values[flat]


def uses_time(g: Any) -> bool:
    """Whether a dynamic game's costs or constraints use the absolute time ``t`` (no name of a dynamic game is t)."""
    if getattr(g, "kind", None) != "dynamic":
        return False
    texts: list[str] = []
    for a in g.agents:
        texts += [a.stage_cost, a.terminal_cost] + [c if isinstance(c, str) else c.expr for c in a.constraints]
    texts += [c if isinstance(c, str) else c.expr for c in g.shared_constraints]
    return any(_TIME.search(text) for text in texts)


class RuntimeLayout:
    """The runtime vector p of one game: its entries, their declared values, and p at a sampling time."""

    def __init__(self, g: Any, sampling_time: float, tables: dict[str, Table] | None = None):
        self.dynamic = g.kind == "dynamic"
        self.horizon = g.horizon if self.dynamic else None
        self.dt = float(sampling_time)
        self.time = uses_time(g)
        self.entries: dict[str, Entry] = {}
        start = 1 if self.time else 0
        tables = tables or {}
        for name, spec in g.runtime.items():
            kind, shape, default = _declared(spec, self.horizon)
            table = tables.get(name)
            if spec.file is not None:
                kind, shape = "stages", (self.horizon + 2,)
                default = np.full(shape, np.nan) if table is None else table.at(self.stage_times(0.0))
            self.entries[name] = Entry(name, kind, shape, start, default, table)
            start += self.entries[name].size
        self.size = start

    def stage_times(self, t_k: float) -> np.ndarray:
        """The times of the stages 0..T + 1 at the sampling time t_k."""
        return t_k + self.dt * np.arange(self.horizon + 2)

    def vector(self, t_k: float = 0.0, values: dict[str, Any] | None = None) -> np.ndarray:
        """p at the sampling time t_k: the time, the data files at the stages' times, every other parameter at its
        declared value, except those ``values`` gives."""
        p = np.empty(self.size)
        if self.time:
            p[0] = t_k
        times = self.stage_times(t_k) if self.dynamic else None
        for e in self.entries.values():
            p[e.slice] = e.default if e.table is None else e.table.at(times)
        for name, value in (values or {}).items():
            e = self.entries.get(name)
            if e is None:
                known = ", ".join(self.entries) or "none"
                raise InputError(f"runtime value for {name!r}: not a runtime parameter of this game (runtime "
                                 f"parameters: {known})")
            p[e.slice] = self.checked(e, value)
        return p

    def checked(self, e: Entry, value: Any) -> np.ndarray:
        """A value given at run time for ``e``, flattened: its shape must be e's (a per-stage table also takes one
        number for every stage, or T + 1 values whose last serves the terminal cost too)."""
        try:
            v = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"runtime value for {e.name!r}: {_shown(value)} is not a number or an array of "
                             "numbers") from None
        if e.kind == "stages":
            v = _over_stages(v, e.shape[0])
        if v.shape != e.shape:
            want = "one number" if not e.shape else f"shape {e.shape}"
            if e.kind == "stages":
                want = f"one number or {e.shape[0] - 1} or {e.shape[0]} values (stages 0..T, T+1)"
            raise InputError(f"runtime value for {e.name!r}: has shape {v.shape}, the parameter needs {want}")
        if not np.all(np.isfinite(v)):
            raise InputError(f"runtime value for {e.name!r}: not finite ({_shown(value)})")
        return v.reshape(-1)

    def record(self, p: np.ndarray) -> dict[str, Any]:
        """p by name, as plain data (numbers and lists): what the log and summary.json record; ``t`` the time."""
        out: dict[str, Any] = {}
        if self.time:
            out["t"] = float(p[0])
        for e in self.entries.values():
            v = p[e.slice]
            out[e.name] = float(v[0]) if e.kind == "scalar" else v.reshape(e.shape).tolist()
        return out

    def symbols(self, p: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        """The expression environment of p's symbols: (names valid at every stage, per-stage tables). A scalar is
        its symbol; a vector or matrix a :class:`SymbolTable` under ``name + '[]'``; a per-stage parameter is filled
        in per stage by :meth:`at_stage`."""
        common: dict[str, Any] = {}
        stages: dict[str, Any] = {}
        for e in self.entries.values():
            values = [p[k] for k in range(e.start, e.start + e.size)]
            if e.kind == "scalar":
                common[e.name] = values[0]
            elif e.kind == "stages":
                stages[e.name] = values
                common[e.name + "[]"] = SymbolTable(e, values)
            else:
                common[e.name + "[]"] = SymbolTable(e, values)
        return common, stages

    def at_stage(self, env: dict, p: Any, stages: dict[str, Any], tau: int) -> None:
        """``env`` at stage tau (T + 1: the terminal cost): this stage's per-stage values and time."""
        for name, values in stages.items():
            env[name] = values[tau]
        if self.time:
            env["t"] = p[0] + tau * self.dt


def _declared(spec: Any, horizon: int | None) -> tuple[str, tuple[int, ...], np.ndarray]:
    """The kind, shape and flattened value of a runtime parameter as declared (its value checked by the config)."""
    value = spec.value
    if spec.per_stage:
        n = horizon + 2
        return "stages", (n,), _over_stages(np.asarray(0.0 if value is None else value, dtype=float), n)
    if value is None:
        return "scalar", (), np.zeros(1)
    v = np.asarray(value, dtype=float)
    kind = {0: "scalar", 1: "vector", 2: "matrix"}[v.ndim]
    return kind, v.shape, v.reshape(-1)


def _over_stages(v: np.ndarray, n: int) -> np.ndarray:
    """Per-stage values as given (one number for every stage, or T + 1 values whose last serves the terminal cost
    too) over the n = T + 2 stages; any other shape as it is (the caller checks it)."""
    if v.ndim == 0:
        return np.full(n, float(v))
    if v.ndim == 1 and v.size == n - 1:
        return np.append(v, v[-1])
    return v


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ---------------------------------------------------------------------------------------------
# Data files
# ---------------------------------------------------------------------------------------------


class TableError(ValueError):
    """A data file that cannot be used; the message says why (the config check adds where it is named)."""


def read_table(path: Path, column: str | int, time: str | int, interpolation: str) -> Table:
    """One value column and the time column of a CSV file (a header row of names, then numbers) or a .npy file (a
    structured array with named fields, or a 2-D array whose columns are given by number). The file is only read."""
    if not path.exists():
        raise TableError(f"{path}: no such file")
    if not path.is_file():
        raise TableError(f"{path}: not a regular file")
    if path.suffix.lower() == ".npy":
        columns = _npy_columns(path)
    else:
        columns = _csv_columns(path)
    names = list(columns)

    def pick(key: str | int, what: str) -> np.ndarray:
        if isinstance(key, int) and not isinstance(key, bool):
            if not 0 <= key < len(names):
                raise TableError(f"{path}: has no {what} column {key} (columns 0..{len(names) - 1})")
            key = names[key]
        if key not in columns:
            raise TableError(f"{path}: has no {what} column {key!r} (columns: {', '.join(map(str, names))})")
        return columns[key]

    t, v = pick(time, "time"), pick(column, "value")
    if t.size < 1:
        raise TableError(f"{path}: has no rows")
    for arr, what in ((t, f"time column {time!r}"), (v, f"column {column!r}")):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise TableError(f"{path}: {what} has a value that is not a finite number in data row {bad[0] + 1}")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise TableError(f"{path}: the times must increase (data row {k + 2}: {t[k + 1]:g} after {t[k]:g})")
    return Table(t.copy(), v.copy(), interpolation, str(path))


def _csv_columns(path: Path) -> dict[str | int, np.ndarray]:
    import csv

    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    except UnicodeDecodeError:
        raise TableError(f"{path}: not a text (CSV) file") from None
    if not rows:
        raise TableError(f"{path}: is empty (a CSV table needs a header row of column names)")
    header = [c.strip() for c in rows[0]]
    data = np.full((len(rows) - 1, len(header)), np.nan)
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise TableError(f"{path}: data row {i + 1} has {len(row)} fields, the header {len(header)}")
        for j, cell in enumerate(row):
            try:
                data[i, j] = float(cell)
            except ValueError:
                raise TableError(f"{path}: data row {i + 1}, column {header[j]!r}: {cell.strip()[:40]!r} is not a "
                                 "number") from None
    return {name: data[:, j] for j, name in enumerate(header)}


def _npy_columns(path: Path) -> dict[str | int, np.ndarray]:
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as e:
        raise TableError(f"{path}: not a readable .npy array ({e})") from None
    if arr.dtype.names:
        try:
            return {n: np.asarray(arr[n], dtype=float).reshape(-1) for n in arr.dtype.names}
        except (TypeError, ValueError):
            raise TableError(f"{path}: its fields must be numbers") from None
    if arr.ndim != 2 or not np.issubdtype(arr.dtype, np.number):
        raise TableError(f"{path}: a .npy table is a 2-D array of numbers (columns by number) or a structured array")
    return {j: np.asarray(arr[:, j], dtype=float) for j in range(arr.shape[1])}


def data_path(source: str | None, file: str) -> Path:
    """A data file's path: relative to the config file's folder (to the working directory for a config dict)."""
    path = Path(file)
    if not path.is_absolute() and source is not None:
        path = Path(source).parent / path
    return path


def read_tables(cfg: Any) -> dict[str, Table]:
    """The data files of a config's runtime parameters, read once per config (kept with it)."""
    cached = cfg.__dict__.get("_runtime_tables")
    if cached is None:
        cached = {name: read_table(data_path(cfg.source, spec.file), spec.column if spec.column is not None else name,
                                   spec.time, spec.interpolation)
                  for name, spec in cfg.game.runtime.items() if spec.file is not None}
        cfg.__dict__["_runtime_tables"] = cached
    return cached


def runtime_layout(cfg: Any) -> RuntimeLayout | None:
    """The runtime layout of a config's game (None where it has no runtime parameters and does not use t)."""
    cached = cfg.__dict__.get("_runtime_layout")
    if cached is None:
        layout = RuntimeLayout(cfg.game, cfg.run.sampling_time, read_tables(cfg))
        cached = cfg.__dict__["_runtime_layout"] = (layout if layout.size else None,)
    return cached[0]


def needed_span(cfg: Any) -> tuple[float, float]:
    """The times a run of ``cfg`` reads its data files at: from 0 to the last stage of the last sampling time."""
    g = cfg.game
    return 0.0, (cfg.run.steps + g.horizon) * cfg.run.sampling_time


class References:
    """The references a game declares for its states (``game.references``): each an expression of parameters,
    runtime values and the time t, evaluated at a sampling time from the values in force (per-stage values at stage
    0). What the log records with the runtime values, and the figures draw with the tracking error x - r."""

    def __init__(self, cfg: Any, layout: RuntimeLayout | None):
        g = cfg.game
        self.layout = layout
        self.parameters = dict(g.parameters)
        self.trees = {state: parse_expression(text) for state, text in getattr(g, "references", {}).items()}
        self.index = {s: k for k, s in enumerate(getattr(g, "states", []))}

    def __bool__(self) -> bool:
        return bool(self.trees)

    def at(self, t_k: float, p: np.ndarray) -> dict[str, float]:
        """r(t_k) of every referenced state."""
        env: dict[str, Any] = dict(self.parameters)
        if self.layout is not None:
            common, stages = self.layout.symbols(p)
            env.update(common)
            env.update({name: values[0] for name, values in stages.items()})
        env.setdefault("t", t_k)
        fns = numpy_functions()
        with np.errstate(all="ignore"):
            return {state: float(evaluate(tree, env, fns)) for state, tree in self.trees.items()}

    def errors(self, x: np.ndarray, values: dict[str, float]) -> dict[str, float]:
        """x_s - r_s of every referenced state s."""
        return {state: float(x[self.index[state]] - r) for state, r in values.items()}
