"""Experiment configs: strict pydantic models, loading, overrides, resolved YAML.

``load_config`` reads a YAML file (or a dict), applies overrides, validates the document
against the models below (unknown keys are errors), then checks what a schema cannot: names,
expressions (parsed, never evaluated as Python), shapes. Every problem becomes one line
``file:line:column: field.path: message``.
"""

from __future__ import annotations

import hashlib
import math
import re
from pathlib import Path
from types import UnionType
from typing import Annotated, Any, Literal, Union, get_args, get_origin

import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    PlainValidator,
    PrivateAttr,
    Tag,
    ValidationError,
    model_validator,
)
from pydantic_core import PydanticCustomError

from ..errors import ConfigError, InputError, did_you_mean, shorten
from .expand import Expander, expands
from .expr import (
    CONSTANTS,
    FUNCTIONS,
    INTEGER_OPERATORS,
    Binary,
    Constraint,
    Expression,
    ExpressionError,
    Index,
    Name,
    check_names,
    children,
    evaluate,
    names_in,
    nodes,
    numpy_functions,
    parse_cache,
    parse_constraint,
    parse_expression,
    unparse,
)
from .parts import constraint_agents as constraint_agents  # (the compiler reads these three from here)
from .parts import constraint_stages as constraint_stages
from .parts import constraint_text as constraint_text
from .parts import sparse_obstacles
from .runtime import SymbolTable, TableError, data_path, needed_span, read_table, runtime_layout
from .size import Size, estimate, from_extent
from .yaml_source import PathKey, SourceMap, parse_yaml, read_yaml
from .yaml_source import dotted as show_path

CONFIG_VERSION = 1
_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _number_to_text(v: Any) -> Any:
    # `terminal_cost: 0` is an expression too.
    if isinstance(v, bool):
        return v
    if isinstance(v, int | float):
        return repr(v) if isinstance(v, float) else str(v)
    return v


Expr = Annotated[str, BeforeValidator(_number_to_text)]


class Strict(BaseModel):
    # numbers are finite (.nan and .inf are refused) except where a field says otherwise
    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False)


def _bound(side: str, unbounded: float) -> Any:
    def check(v: Any) -> Any:
        if isinstance(v, float) and math.isnan(v):
            raise ValueError(f"the {side} bound is NaN; leave it out (or write {unbounded:+}) for no bound"
                             .replace("inf", ".inf"))
        if isinstance(v, float) and v == -unbounded:
            raise ValueError(f"{side} bound {v:+} admits no value".replace("inf", ".inf"))
        return v

    return AfterValidator(check)


def _not_a_boolean(v: Any) -> Any:
    # YAML's true/false would otherwise be read as the bound 1 or 0
    if isinstance(v, bool):
        raise PydanticCustomError("float_type", "Input should be a valid number, not a boolean")
    return v


def _finite_number(x: Any) -> float:
    if isinstance(x, bool) or not isinstance(x, int | float):
        raise PydanticCustomError("float_type", "Input should be a valid number")
    if not math.isfinite(x):
        raise PydanticCustomError("finite_number", "Input should be a finite number")
    return float(x)


def _start_value(v: Any) -> float | list[float]:
    """A start value: a finite number, or (an input of a dynamic game) a list of them, one per stage."""
    if isinstance(v, list):
        return [_finite_number(x) for x in v]
    return _finite_number(v)


class Variable(Strict):
    """A decision variable: bounds (constraints of its owner) and a start value; ±.inf is no bound."""

    lower: Annotated[float | None, Field(allow_inf_nan=True), BeforeValidator(_not_a_boolean),
                     _bound("lower", -math.inf)] = None
    upper: Annotated[float | None, Field(allow_inf_nan=True), BeforeValidator(_not_a_boolean),
                     _bound("upper", math.inf)] = None
    start: Annotated[float | list[float], PlainValidator(_start_value)] = 0.0  # inputs: may be a list


def _names_to_variables(v: Any) -> Any:
    # `inputs: [u1, u2]` is shorthand for `inputs: {u1: {}, u2: {}}`.
    if isinstance(v, list):
        if not all(isinstance(x, str) for x in v):
            return v  # let the dict validation report it
        return {name: {} for name in v}
    return v


Variables = Annotated[dict[str, Variable], BeforeValidator(_names_to_variables)]


class StaticAgent(Strict):
    name: str
    variables: Variables
    cost: Expr
    constraints: list[Expr] = Field(default_factory=list)


class StagedConstraint(Strict):
    """A constraint of a dynamic game imposed at some stages only (``stages``: tau values in 0..T)."""

    expr: Expr
    stages: list[int] = Field(min_length=1)


class SharedConstraint(Strict):
    """A shared constraint with options: carried by the named ``agents`` only (default: every agent), and in a
    dynamic game imposed at some ``stages`` only (default: every stage)."""

    expr: Expr
    stages: list[int] | None = Field(default=None, min_length=1)
    agents: list[str] | None = Field(default=None, min_length=1)


def _constraint_tag(v: Any) -> str:
    # a constraint is its text, or a mapping with options: pydantic reports the problems of the one it is
    return "options" if isinstance(v, dict | BaseModel) else "text"


StageConstraint = Annotated[Annotated[Expr, Tag("text")] | Annotated[StagedConstraint, Tag("options")],
                            Discriminator(_constraint_tag)]
SharedSpec = Annotated[Annotated[Expr, Tag("text")] | Annotated[SharedConstraint, Tag("options")],
                       Discriminator(_constraint_tag)]


class DynamicAgent(Strict):
    name: str
    inputs: Variables
    stage_cost: Expr
    terminal_cost: Expr = "0"
    constraints: list[StageConstraint] = Field(default_factory=list)


class LinearDynamics(Strict):
    """x(t+1) = A x(t) + B u(t); states in `states` order, inputs in agent order."""

    A: list[list[float]]
    B: list[list[float]]


class ContinuousDynamics(Strict):
    """dx/dt = f(x, u) (``ode``: one expression per state), integrated over one sampling time ``dt`` by an
    explicit Runge-Kutta method with the input held constant: x(t+1) is the integrator's step from x(t)."""

    ode: dict[str, Expr]
    integrator: Literal["euler", "rk2", "rk3", "rk4"] = "rk4"
    dt: float = Field(gt=0, allow_inf_nan=False)


def _dynamics_tag(v: Any) -> str:
    # the form whose keys were written; without ode, two keys of the ode's form (or misspellings of them) are still an
    # ode with a misspelt key, not discrete dynamics of states named so, and are reported in the ode's words
    if isinstance(v, LinearDynamics) or (isinstance(v, dict) and ("A" in v or "B" in v)):
        return "linear"
    if isinstance(v, ContinuousDynamics) or (isinstance(v, dict) and "ode" in v):
        return "continuous"
    keys = [k for k in v if isinstance(k, str)] if isinstance(v, dict) else []
    if sum(k in ("integrator", "dt") or bool(did_you_mean(k, ("ode", "integrator"))) for k in keys) >= 2:
        return "continuous"
    return "expressions"


Dynamics = Annotated[
    Annotated[LinearDynamics, Tag("linear")] | Annotated[ContinuousDynamics, Tag("continuous")]
    | Annotated[dict[str, Expr], Tag("expressions")],
    Discriminator(_dynamics_tag),
]


def _runtime_shorthand(v: Any) -> Any:
    # `r: 0.5` and `goal: [1, 2]` are runtime parameters with that value
    return {"value": v} if not isinstance(v, dict) else v


class RuntimeParameter(Strict):
    """A runtime parameter: an input of the compiled functions, like the plant state (gnerun.language.runtime). Its
    value changes without recompiling: from ``value``, a data file, the Python API or a sweep."""

    value: float | list[float] | list[list[float]] | None = Field(
        None, description="a number, a vector (name[i]), a matrix (name[i][j]); per_stage: one number for every "
                          "stage, or a list over the stages 0..T (or 0..T+1, T+1 being the terminal cost's)")
    per_stage: bool = Field(False, description="a value for every stage tau: `name` is this stage's, name[tau + 1] "
                                               "the next one's (stage indices from 0, like tau)")
    file: str | None = Field(None, description="a data table (CSV with a header row, or .npy): the value at each "
                                               "stage's time t_k + tau * dt, interpolated (relative to the config)")
    column: str | int | None = Field(None, description="the file's column (default: the parameter's name)")
    time: str | int = Field("t", description="the file's time column")
    interpolation: Literal["linear", "hold"] = Field("linear", description="linear, or zero-order hold")


Runtime = dict[str, Annotated[RuntimeParameter, BeforeValidator(_runtime_shorthand)]]


class StaticGame(Strict):
    kind: Literal["static"]
    parameters: dict[str, float] = Field(default_factory=dict)
    runtime: Runtime = Field(default_factory=dict)
    agents: list[StaticAgent] = Field(min_length=1)
    shared_constraints: list[SharedSpec] = Field(default_factory=list)
    equilibrium: Literal["generalized", "variational"] = "generalized"


class DynamicGame(Strict):
    kind: Literal["dynamic"]
    horizon: int = Field(ge=0, le=10_000, description="T: inputs a(0..T) per agent")
    states: list[str] = Field(min_length=1)
    dynamics: Dynamics
    x0: list[float]
    parameters: dict[str, float] = Field(default_factory=dict)
    runtime: Runtime = Field(default_factory=dict)
    references: dict[str, Expr] = Field(default_factory=dict, description="state: the reference it tracks, an "
                                        "expression of parameters, runtime values and t (logged, and drawn by the "
                                        "figures with the tracking error)")
    agents: list[DynamicAgent] = Field(min_length=1)
    shared_constraints: list[SharedSpec] = Field(default_factory=list)
    equilibrium: Literal["generalized", "variational"] = "generalized"


Game = Annotated[StaticGame | DynamicGame, Field(discriminator="kind")]


class SolverConfig(Strict):
    kind: Literal["ssn", "jn", "distributed"] = "ssn"
    tol: float = Field(1e-10, gt=0, description="stop when ||Phi(z)||_2 <= tol")
    max_iter: int = Field(300, ge=0, le=1_000_000)
    complementarity: Literal["min", "fischer_burmeister"] = "min"
    tie_tol: float = Field(
        1e-12, ge=0, description="|-g_j - lambda_j| <= tie_tol is a tie; the multiplier row is chosen"
    )
    min_rcond: float = Field(1e-14, ge=0, description="JPhi with reciprocal condition below this is singular")
    globalization: Literal["auto", "hybrid", "interior_point", "line_search", "none"] = Field(
        "auto", description="ssn (and the inner ssn of distributed): hybrid, the default (auto), takes the paper's "
                            "min-map steps where they decrease ||Phi|| and an interior-point phase elsewhere; none: "
                            "the paper's pure local method; line_search: Armijo backtracking on 1/2||Phi||^2; "
                            "interior_point: the interior-point phase alone")
    divergence_limit: float = Field(1e12, gt=0, description="||z||_inf beyond this is divergence")
    formulation: Literal["auto", "condensed", "sparse"] = Field(
        "auto", description="dynamic games, ssn: states eliminated (condensed, dense) or kept as unknowns (sparse, "
                            "linear in the horizon); auto: sparse for long horizons. Same iterates either way")
    compile: Literal["auto", "compiled", "interpreted"] = Field(
        "auto", description="the KKT system as C compiled once and cached, where a C compiler is found, or evaluated "
                            "by CasADi's interpreter (interpreted). Sparse formulation: its stage functions (auto and "
                            "compiled); condensed formulation and static games, ssn: the condensed KKT function "
                            "(compiled only; auto keeps it interpreted). Same iterates up to rounding")
    # kind: distributed (agent-distributed proximal response); ignored by ssn and jn
    scheme: Literal["jacobi", "gauss_seidel"] = "jacobi"
    tau: float = Field(1.0, ge=0, description="proximal weight: tau/2 ||a_i - abar_i||^2")
    inner: Literal["ssn", "jn"] = "ssn"
    inner_max_iter: int = Field(20, ge=1, le=1_000_000, description="inner Newton iterations per proximal response")


def _scale(v: Any) -> float | list[float]:
    """A plant disturbance's scale: one number, or a list of numbers (one per state)."""
    if isinstance(v, list):
        return [_number(x, f"entry {i + 1} is not a number") for i, x in enumerate(v)]
    return _number(v, "must be a number or a list of numbers (one per state)")


def _number(x: Any, problem: str) -> float:
    if isinstance(x, str):  # YAML reads 1e-3 as a string: a number written so is a number, as in every float field
        try:
            return float(x)
        except ValueError:
            pass
    if isinstance(x, bool) or not isinstance(x, int | float | str):
        raise PydanticCustomError("float_type", problem)
    if isinstance(x, str):
        raise PydanticCustomError("float_type", problem)
    return float(x)


class PlantDisturbance(Strict):
    """w(t) in x(t+1) = f(x(t), u(t)) + w(t): gaussian (standard deviation ``scale``), uniform on
    [-scale, scale], or the constant ``scale``; ``scale`` is one number or one per state."""

    kind: Literal["none", "gaussian", "uniform", "constant"] = "none"
    scale: Annotated[float | list[float], PlainValidator(_scale)] = 0.0
    seed: Seed = 0


class DisturbanceConfig(Strict):
    kind: Literal["none", "jacobian_noise", "residual", "pseudogradient"] = "none"
    scale: float = Field(0.0, ge=0)
    seed: Seed = 0
    distribution: Literal["normal", "uniform"] = "normal"
    plant: PlantDisturbance = Field(default_factory=PlantDisturbance)


def _one_or_list(v: Any) -> Any:
    return [v] if isinstance(v, int) and not isinstance(v, bool) else v


class RunConfig(Strict):
    K: Annotated[list[Annotated[int, Field(ge=1, le=100_000)]], BeforeValidator(_one_or_list)] = Field(
        default_factory=lambda: [5], min_length=1, max_length=1000,
        description="iteration budgets; one number is a list of one")
    steps: int = Field(30, ge=1, le=10_000_000)
    warm_start: Literal["previous", "shift"] = Field(
        "shift", description="shift: the plan applied at the last sampling time without its stage 0, its last stage "
                             "repeated (the MPC convention); previous: the last iterate as it is (the paper's rule)")
    initial: Literal["solve", "start"] = Field(
        "solve", description="simulate: solve: the first sampling time is solved to tolerance (at most "
                             "solver.max_iter steps), the budget K applies from the second; start: K steps from the "
                             "start values at every sampling time (the paper's rule)")
    safeguard: Literal["fallback", "none"] = Field(
        "fallback", description="simulate: fallback: an iterate that is not converged is applied only if it is the "
                                "best plan at hand (its first step safe, the least ||Phi||), otherwise the shifted "
                                "previous plan or a better earlier iterate; none: the K-th iterate is applied (the "
                                "paper's rule)")
    on_failure: Literal["continue", "stop"] = Field(
        "continue", description="a failed solver step in simulate: continue (the plant gets the inputs of the "
                                "last iterate before it) or stop that closed loop there")
    reference: Literal["exact", "none"] = Field(
        "exact", description="exact: also solve for the exact solution z* (z*(t) in simulate) and report the "
                             "errors ||z - z*||; none: skip it, for runs where only the solution or the loop matters")
    certificate: bool = Field(
        True, description="solve: check the equilibrium by each agent's best response (and restart from an "
                          "improving one); false: the KKT residual alone")
    log_writer: Literal["inline", "process"] = Field(
        "inline", description="simulate: who writes the run log: inline (the loop's own process, between sampling "
                              "times) or process (a writer process of its own, to which a sampling time hands plain "
                              "numbers: on the 41-knot MPC merge the log then costs the loop about 0.08 ms a "
                              "sampling time instead of 0.5 ms)")
    sampling_time: float | None = Field(
        None, gt=0, description="seconds from one sampling time t to the next: the time axis of simulate's log "
                                "(log_time = t x sampling_time); default: dynamics.dt of an ode, else 1")


MIN_SAMPLING_TIME = 1e-9  # the run log's resolution: log_time is in nanoseconds
MAX_LOG_SECONDS = (2**63 - 1) / 1e9  # the last time a run log can stamp (signed 64-bit nanoseconds, as readers take it)
MAX_NAME_BYTES = 100  # runs/<name>-<UTC timestamp>/ stays well inside a file name's 255 bytes


def safe_name(name: str, names: str = "the run directory runs/<name>-<time>/") -> str:
    """A config's name (or a sweep's) is one plain path component: it ``names`` a directory under runs/."""
    shown = repr(name) if len(name) <= 40 else repr(name[:37] + "...")
    if not name:
        raise ValueError(f"the name is empty; it names {names}")
    if "\x00" in name:
        raise ValueError(f"{shown} contains a NUL character; a name is one file name")
    if "/" in name or "\\" in name:
        raise ValueError(f"{shown} is not one path component (no / or \\): it names {names}")
    if name.startswith("."):
        raise ValueError(f"{shown} starts with '.'; a name is a visible file name (not . or .. or hidden)")
    if not name.isprintable():
        raise ValueError(f"{shown} contains control characters; a name is one printable file name")
    size = len(name.encode())
    if size > MAX_NAME_BYTES:
        raise ValueError(f"{shown} is {size} bytes long; a name is at most {MAX_NAME_BYTES} (it names {names})")
    return name


Seed = Annotated[int, Field(ge=0, le=2**64 - 1, description="seed of numpy's random generator (0 .. 2**64 - 1)")]


class Config(Strict):
    version: Literal[1] = CONFIG_VERSION
    name: Annotated[str, AfterValidator(safe_name)] = "run"
    game: Game
    solver: SolverConfig = Field(default_factory=SolverConfig)
    disturbance: DisturbanceConfig = Field(default_factory=DisturbanceConfig)
    run: RunConfig = Field(default_factory=RunConfig)

    _source: str | None = PrivateAttr(default=None)
    _size: Any = PrivateAttr(default=None)

    @model_validator(mode="after")
    def _fill_sampling_time(self) -> Config:
        if self.run.sampling_time is None:
            dynamics = getattr(self.game, "dynamics", None)
            self.run.sampling_time = dynamics.dt if isinstance(dynamics, ContinuousDynamics) else 1.0
        return self

    def __eq__(self, other: object) -> bool:
        # the same experiment, wherever it was loaded from
        return isinstance(other, Config) and self.model_dump() == other.model_dump()

    __hash__ = None  # type: ignore[assignment]

    @property
    def source(self) -> str | None:
        """The file this config was loaded from, if any."""
        return self._source

    @property
    def size(self) -> Size:
        """The estimated size of the game (:class:`gnerun.language.size.Size`), computed before building it."""
        if self._size is None:
            self._size = estimate(self)
        return self._size

    def size_warnings(self, command: str) -> list[str]:
        """Warnings about the size of what ``command`` (solve, simulate, validate: both) would build and run."""
        warnings = list(self.size.problems()[1])
        if command in ("simulate", "validate") and self.game.kind == "dynamic":
            warnings.append(self.size.loop_warning())
        if command in ("solve", "validate") and self.run.certificate:
            warnings.append(self.size.certificate_warning())
        return [w for w in warnings if w]

    def resolved_yaml(self, files: dict[str, str] | None = None) -> str:
        """The config with every default filled in, as YAML (what runs write to config.yaml); a game without
        runtime parameters is written without the empty section. ``files`` gives runtime parameters' data files
        new paths (a run directory's copies)."""
        data = self.model_dump(mode="json")
        for optional in ("runtime", "references"):
            if not data["game"].get(optional) and optional in data["game"]:
                data["game"].pop(optional)
        for name, file in (files or {}).items():
            data["game"]["runtime"][name]["file"] = file
        return dump_yaml(data)

    def config_hash(self, resolved: str | None = None) -> str:
        """sha256 of :meth:`resolved_yaml` (``resolved``: that text, where the caller has it already)."""
        return hashlib.sha256((self.resolved_yaml() if resolved is None else resolved).encode()).hexdigest()


# ---------------------------------------------------------------------------------------------
# YAML output
# ---------------------------------------------------------------------------------------------


# libyaml's emitter where PyYAML was built with it: the same text as PyYAML's own (tests/test_config.py), 10-20x
# faster on a long expanded game (the config.yaml of 200 Cournot firms: 0.4 s -> 0.02 s)
_SafeDumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _Dumper(_SafeDumper):  # type: ignore[misc, valid-type]
    pass


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flow = all(isinstance(x, int | float | bool) or x is None for x in data) or (
        all(isinstance(x, list) for x in data) and all(isinstance(y, int | float) for x in data for y in x)
    )
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow and bool(data))


_Dumper.add_representer(list, _represent_list)


def dump_yaml(data: Any) -> str:
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)


# ---------------------------------------------------------------------------------------------
# Overrides
# ---------------------------------------------------------------------------------------------


def parse_override(text: str) -> tuple[str, Any]:
    """``"a.b=value"`` -> ``("a.b", value)``, the value read as YAML (``run.K=[1,7]``)."""
    if "=" not in text:
        raise InputError(f"--set {shorten(text, 100)}: expected key.path=value")
    key, _, raw = text.partition("=")
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise InputError(f"--set {shorten(text, 100)}: expected key.path=value")
    if not raw.strip():
        return key, ""
    try:  # the same reader as config files: plain data only, bounded depth and size
        value, _ = parse_yaml(raw, "--set")
    except ConfigError as e:
        problem = re.sub(r"^--set(:\d+:\d+)?: ", "", e.problems[0])
        raise InputError(f"--set {shorten(text, 100)}: the value is not valid: {problem}") from None
    return key, value


def override_label(key: str, value: Any) -> str:
    """How an override given as Python data is named in messages: ``overrides['solver.tol'] = -1``."""
    return f"overrides[{key!r}] = {value!r}"


def _apply_override(data: dict, key: str, value: Any, smap: SourceMap, shown: str) -> None:
    """Set ``key`` (a dotted path) to ``value``; ``shown`` names the override in messages (``--set a.b=1``)."""
    # a list index is a plain decimal number (Unicode digits and 20,000-digit numbers are names, found nowhere)
    parts: list[str | int] = [int(p) if p.isascii() and p.isdigit() and len(p.lstrip("0")) <= 18 else p
                              for p in key.split(".")]
    node: Any = data
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(node, dict):
            if isinstance(part, int):
                part = str(part)
            if last:
                node[part] = value
            else:
                if not isinstance(node.get(part), dict | list):
                    node[part] = {}
                node = node[part]
        elif isinstance(node, list):
            if not isinstance(part, int) or not 0 <= part < len(node):
                raise InputError(f"{shorten(shown, 100)}: {'.'.join(map(str, parts[: i + 1]))}: no such list element")
            if last:
                node[part] = value
            else:
                node = node[part]
        else:
            raise InputError(f"{shorten(shown, 100)}: {'.'.join(map(str, parts[:i]))} is not a mapping")
    smap.overridden[tuple(parts)] = shown


# ---------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------


def load_config(
    path: str | Path | dict | None = None,
    overrides: dict[str, Any] | list[str] | None = None,
    *,
    text: str | None = None,
) -> Config:
    """Load and validate a config file (or ``text``, or a dict: the YAML document as Python data), applying
    ``overrides``; families, templates, sums and definitions are expanded before validation.

    ``overrides`` maps dotted field paths to values (``{"solver.tol": 1e-12}``), or is a list of
    ``"a.b=value"`` strings as given to ``--set``. Raises :class:`ConfigError` with every problem.
    """
    if isinstance(path, dict):
        data, smap = _plain(path, ()), SourceMap("config dict")
        path = None
    elif text is not None:
        data, smap = parse_yaml(text, str(path) if path is not None else "<string>")
    elif path is not None:
        data, smap = read_yaml(path)
    else:
        raise InputError("load_config needs a path or text")
    if not isinstance(data, dict):
        raise ConfigError([f"{smap.locate(())}: the config must be a mapping of fields, got {type(data).__name__}"])
    if is_sweep_spec(data):
        raise ConfigError([f"{smap.locate(())}: a sweep spec, not a config: run it with `gnerun sweep`"])
    items: list[tuple[str, Any, str]] = []
    if isinstance(overrides, dict):
        items = [(k, v, override_label(k, v)) for k, v in overrides.items()]
    elif overrides:
        for o in overrides:
            k, v = parse_override(o)
            items.append((k, v, f"--set {o}"))
    for key, value, shown in items:
        _apply_override(data, key, value, smap, shown)
    if "name" not in data and path is not None:
        data["name"] = Path(str(path)).stem
    if expands(data):
        data, smap = Expander(smap, early_size=estimate_before_expanding).expand(data)
    try:
        cfg = Config.model_validate(data)
    except ValidationError as e:
        raise ConfigError(one_per_template(_validation_problems(e, data, smap))) from None
    cfg._source = str(path) if path is not None else None  # data files are found relative to it
    with parse_cache():  # every expression parsed once, for the checks and the estimate
        problems = check_semantics(cfg, smap)
        if problems:
            raise ConfigError(one_per_template(problems))
        size = estimate(cfg)
    too_large, _ = size.problems()
    if too_large:
        where = ("game", "horizon") if cfg.game.kind == "dynamic" else ("game", "agents")
        raise ConfigError([f"{smap.locate(where)}: {show_path(where)}: {p}" for p in too_large])
    cfg._source = str(path) if path is not None else None
    cfg._size = size
    return cfg


def estimate_before_expanding(extent: Any, game: dict, document: dict) -> Size | None:
    """:func:`gnerun.language.size.from_extent` of a document's game section with its solver and disturbance
    options (:mod:`gnerun.language.expand` refuses a game too large to build before writing it out); None where the
    options do not validate (their validation says why)."""
    try:
        solver = SolverConfig.model_validate(document.get("solver") or {})
        disturbance = DisturbanceConfig.model_validate(document.get("disturbance") or {})
    except (ValidationError, AttributeError, TypeError):
        return None
    return from_extent(extent, game, solver, disturbance)


def _plain(value: Any, path: tuple) -> Any:
    """A copy of a config given as Python data, as YAML would have built it (tuples as lists, numpy scalars as
    numbers); anything else is refused with its place."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str | int | float | bool) and k is not None:
                raise ConfigError([f"config dict, at {show_path(path)}: key {k!r} is not a string or a number"])
            out[k] = _plain(v, path + (k,))
        return out
    if isinstance(value, list | tuple):
        return [_plain(v, path + (i,)) for i, v in enumerate(value)]
    if value is None or isinstance(value, str | bool | int | float):
        return value
    item = getattr(value, "item", None)  # numpy scalars
    if callable(item) and getattr(value, "shape", None) == ():
        return _plain(item(), path)
    raise ConfigError([f"config dict, at {show_path(path)}: {type(value).__name__} is not a config value (use "
                       "numbers, strings, lists and dicts)"])


# keys of earlier versions of the config format, and what replaced them
RENAMED = {
    ("solver", "line_search"): "solver.line_search was replaced by solver.globalization (line_search: true is "
                               "globalization: line_search; the default, auto, is the globalized hybrid method)",
}


_COPY = re.compile(r"^(?P<where>.*?) \(for (?P<note>[^()]*)\): (?P<rest>[^\n]*)(?P<tail>\n.*)?$", re.DOTALL)


_SUGGESTION = re.compile(r"; did you mean '[^']*'\?")


def one_per_template(problems: list[str]) -> list[str]:
    """One message per template: the same problem in several copies of a family (at the template's file:line:column,
    the same field and message but for the numbers the copies' indices write in, and the names suggested) is reported
    once, for the first copy, with the index values of all (``file:line:column (in 6 copies, for i = 1..6): ...``);
    a problem found twice (a definition's, wherever it is used) once."""
    groups: dict[tuple[str, str], list[tuple[str, dict[str, int]]]] = {}
    order: list[tuple[str, str] | str] = []
    seen: set[str] = set()
    for p in problems:
        m = _COPY.match(p)
        if m is None:
            if p not in seen:  # (a definition's problem is found wherever it is used)
                seen.add(p)
                order.append(p)
            continue
        key = (m["where"], re.sub(r"\d+", "#", _SUGGESTION.sub("", m["rest"])))
        if key not in groups:
            groups[key] = []
            order.append(key)
        bindings = dict((k, int(v)) for k, v in re.findall(r"(\w+) = (-?\d+)", m["note"]))
        groups[key].append((p, bindings))
    out = []
    for item in order:
        if isinstance(item, str):
            out.append(item)
            continue
        copies = groups[item]
        first = _COPY.match(copies[0][0])
        if len(copies) == 1 or first is None:
            out.append(copies[0][0])
            continue
        out.append(f"{first['where']} (in {len(copies)} copies, for {copies_text([b for _, b in copies])}): "
                   f"{first['rest']}{first['tail'] or ''}")
    return out


def copies_text(bindings: list[dict[str, int]]) -> str:
    """The index values of several copies of a family: ``i = 1..6``; ``i = 1..3, j = 1..2`` (all pairs);
    ``(i, j) = (1, 2), (1, 3), ..., (5, 6)`` (some)."""
    names = list(bindings[0])
    values = [sorted({b.get(n, 0) for b in bindings}) for n in names]
    tuples = sorted({tuple(b.get(n, 0) for n in names) for b in bindings})
    if math.prod(len(v) for v in values) == len(tuples):  # every combination: each index's values
        return ", ".join(f"{n} = {_ranges(v)}" for n, v in zip(names, values, strict=True))
    shown = [f"({', '.join(map(str, t))})" for t in tuples]
    if len(shown) > 4:
        shown = shown[:3] + ["...", shown[-1]]
    return f"({', '.join(names)}) = {', '.join(shown)}"


def _ranges(values: list[int]) -> str:
    """``1..4, 6, 8..9`` for [1, 2, 3, 4, 6, 8, 9]."""
    runs: list[list[int]] = []
    for v in values:
        if runs and v == runs[-1][1] + 1:
            runs[-1][1] = v
        else:
            runs.append([v, v])
    return ", ".join(str(a) if a == b else f"{a}..{b}" if b > a + 1 else f"{a}, {b}" for a, b in runs)


def _validation_problems(err: ValidationError, data: Any, smap: SourceMap) -> list[str]:
    """The schema's problems, the cause first: an unknown key says which key it may be a misspelling of (and the
    required field it names is then not reported missing), and a field reported missing where an unknown key was
    written comes after that key's problem."""
    problems: list[tuple[PathKey, str, str]] = []  # the place, the kind of problem, the message
    suggested: set[PathKey] = set()  # required fields an unknown key is a misspelling of
    for e in err.errors(include_url=False):
        path = document_path(e["loc"], data)
        dotted = show_path(path, "<config>")
        kind = e["type"]
        if kind == "extra_forbidden":
            where = smap.locate(path, key=True)
            allowed = allowed_keys(e["loc"], path, data)
            given = _value_at_path(data, path[:-1])
            unused = [k for k in allowed if not (isinstance(given, dict) and k in given)]
            hint = did_you_mean(str(path[-1]), unused) if isinstance(path[-1], str) else ""
            if hint:
                suggested.add(path[:-1] + (hint.split("'")[1],))
            msg = RENAMED.get(path[-2:]) or "unknown key" + hint + (f" (allowed here: {', '.join(allowed)})"
                                                                    if allowed else "")
        elif kind == "missing":
            where = smap.locate(path[:-1])
            msg = "required field is missing"
        else:
            where = smap.locate(path)
            msg = e["msg"]
            if kind == "union_tag_invalid" or kind == "literal_error":
                msg = msg.replace("Input tag", "kind")
            elif kind == "value_error":
                msg = msg.removeprefix("Value error, ")
            elif kind == "too_short":
                n = (e.get("ctx") or {}).get("min_length", 1)
                msg = f"needs at least {n} entr{'y' if n == 1 else 'ies'} (it has {len(e['input'])})"
        problems.append((path, kind, f"{where}: {dotted}: {msg}"))
    unknown_at = {path[:-1] for path, kind, _ in problems if kind == "extra_forbidden"}
    first = [(path, kind, text) for path, kind, text in problems
             if not (kind == "missing" and (path in suggested or path[:-1] in unknown_at))]
    for path, kind, text in problems:  # a field missing where an unknown key was written: after that key
        if kind == "missing" and path not in suggested and path[:-1] in unknown_at:
            at = max(i for i, (p, k, _) in enumerate(first) if k == "extra_forbidden" and p[:-1] == path[:-1])
            first.insert(at + 1, (path, kind, text))
    return [text for _, _, text in first]


def document_path(loc: tuple, data: Any) -> PathKey:
    """Map a pydantic error location onto the document, dropping union tags."""
    out: list[str | int] = []
    node = data
    for i, part in enumerate(loc):
        last = i == len(loc) - 1
        if isinstance(node, dict):
            if part in node:
                out.append(part)
                node = node[part]
            elif last:
                out.append(part)
            # else: a union tag such as 'dynamic' or 'linear': not part of the document
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            out.append(part)
            node = node[part]
        elif last:
            out.append(part)
    return tuple(out)


def _value_at_path(data: Any, path: PathKey) -> Any:
    for part in path:
        if isinstance(data, dict) and part in data or isinstance(data, list) and isinstance(part, int):
            data = data[part]
        else:
            return None
    return data


def allowed_keys(loc: tuple, path: PathKey, data: Any, root: type[BaseModel] | None = None) -> list[str]:
    """The keys allowed at the mapping that holds the unknown key of a pydantic error at ``loc`` (``path`` in the
    document): the fields of the model that validated that mapping (the branch of a union its tag names), and the
    template language's keys of that place."""
    model = schema_at(loc[:-1], root or Config)
    if not (isinstance(model, type) and issubclass(model, BaseModel)):
        return []
    keys = list(model.model_fields)  # and the keys the template language reads before (gnerun.language.expand):
    if model in (StaticGame, DynamicGame):
        keys.append("definitions")  # the game's definitions, and for: in an item of a list of the game section
    elif len(path) >= 3 and path[0] == "game" and isinstance(path[-2], int):
        keys.append("for")
    return keys


def _unwrapped(tp: Any) -> Any:
    while get_origin(tp) is Annotated:
        tp = get_args(tp)[0]
    return tp


def _branch(union: Any, tag: Any) -> Any:
    """The member of a union that a pydantic error location's ``tag`` names: a ``Tag``, or the value of a
    discriminating ``Literal`` field (``kind: dynamic``); None if it names none."""
    for member in get_args(union):
        if get_origin(member) is Annotated and any(getattr(m, "tag", None) == tag for m in get_args(member)[1:]):
            return member
        model = _unwrapped(member)
        if isinstance(model, type) and issubclass(model, BaseModel):
            for f in model.model_fields.values():
                if get_origin(f.annotation) is Literal and tag in get_args(f.annotation):
                    return member
    return None


def schema_at(loc: tuple, root: Any = None) -> Any:
    """The type that validated the place ``loc`` of a pydantic error location (whose union tags name the branch that
    was taken), from the model ``root`` (:class:`Config`); None where the location leaves the models."""
    tp: Any = Config if root is None else root
    for part in loc:
        tp = _unwrapped(tp)
        origin = get_origin(tp)
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            field = tp.model_fields.get(part) if isinstance(part, str) else None
            if field is None:
                return None
            tp = field.annotation
        elif origin in (Union, UnionType):
            tp = _branch(tp, part)
        elif origin is list and isinstance(part, int):
            tp = get_args(tp)[0]
        elif origin is dict:
            tp = get_args(tp)[1]
        else:
            return None
        if tp is None:
            return None
    return _unwrapped(tp)


# ---------------------------------------------------------------------------------------------
# Semantic checks: names, expressions, shapes
# ---------------------------------------------------------------------------------------------


def _names_of(text: str) -> set[str]:
    try:
        return parse_expression(text).names
    except ExpressionError:
        return set()  # reported by the check


def is_sweep_spec(data: Any) -> bool:
    """A document with a base config and a grid (and no game of its own): a sweep spec, not a config."""
    return isinstance(data, dict) and "grid" in data and "base" in data and "game" not in data


def check_semantics(cfg: Config, smap: SourceMap) -> list[str]:
    """Every problem a schema cannot see, as ``file:line:column: path: message`` lines."""
    checks = _SemanticChecks(cfg, smap)
    checks.names()
    checks.runtime()
    checks.expressions()
    checks.disturbance()
    checks.solver()
    checks.sampling_time()
    return checks.problems


class _SemanticChecks:
    """The semantic checks of one config, section by section, each problem reported where it was written."""

    def __init__(self, cfg: Config, smap: SourceMap):
        self.cfg, self.smap, self.g = cfg, smap, cfg.game
        self.static = isinstance(self.g, StaticGame)
        self.ode = isinstance(getattr(self.g, "dynamics", None), ContinuousDynamics)  # dt is a name of its expressions
        self.problems: list[str] = []
        self.seen: dict[str, str] = {}  # every name declared so far, and what it is
        self.agent_names: set[str] = set()
        self.kinds: dict[str, str] = {}  # runtime parameters and their kind: scalar, vector, matrix or stages
        self.runtime_ok = True

    def report(self, path: PathKey, message: str, *, key: bool = False, column: int | None = None,
               text: str | None = None) -> None:
        """A problem at ``path`` (its ``key``); at character ``column`` of the expression ``text`` there, where it was
        written (a template's character, :meth:`~gnerun.language.yaml_source.SourceMap.point`), which is shown."""
        if column is not None and text is not None:
            where, path, shown = self.smap.point(path, column, text)
            message += shown
        elif column is not None:
            where = self.smap.locate_in_text(path, column)
        else:
            where = self.smap.locate(path, key=key)
        self.problems.append(f"{where}: {show_path(path)}: {message}")

    def declare(self, name: str, path: PathKey, what: str, *, key: bool = False) -> None:
        if not _IDENTIFIER.match(name):
            self.report(path, f"{what} {name!r} is not a valid name (letters, digits and _, not starting with a digit)",
                        key=key)
        elif name in FUNCTIONS:
            self.report(path, f"{what} {name!r} is the name of a function", key=key)
        elif name in CONSTANTS:
            self.report(path, f"{what} {name!r} is the name of a constant", key=key)
        elif name == "tau" and not self.static:
            self.report(path, f"{what} 'tau' is the name of the stage index", key=key)
        elif name == "t" and not self.static:
            self.report(path, f"{what} 't' is the name of a stage's time in a dynamic game (t_k + tau * dt: "
                              "no clock state is needed)", key=key)
        elif name == "T" and not self.static:
            self.report(path, f"{what} 'T' is the name of the horizon (game.horizon), which {{T}} and ranges "
                              "such as 1..T read", key=key)
        elif name == "dt" and self.ode and what != "parameter":
            self.report(path, f"{what} 'dt' is the name of the sampling time (dynamics.dt) in a game with an ode",
                        key=key)
        elif name in self.seen:
            self.report(path, f"{what} {name!r} is already declared as {self.seen[name]}", key=key)
        else:
            self.seen[name] = what

    # names ------------------------------------------------------------------------------------------
    def names(self) -> None:
        """Parameters, agents, states and the agents' variables or inputs: valid, distinct names, and bounds."""
        g = self.g
        for pname, value in g.parameters.items():
            self.declare(pname, ("game", "parameters", pname), "parameter", key=True)
            if not math.isfinite(value):
                self.report(("game", "parameters", pname), "must be finite")
        for i, agent in enumerate(g.agents):
            if agent.name in self.agent_names:
                self.report(("game", "agents", i, "name"), f"agent {agent.name!r} is declared twice")
            self.agent_names.add(agent.name)
        if not self.static:
            for j, s in enumerate(g.states):
                self.declare(s, ("game", "states", j), "state")
        for i, agent in enumerate(g.agents):
            self._variables(i, agent)

    def _variables(self, i: int, agent: StaticAgent | DynamicAgent) -> None:
        g, static = self.g, self.static
        variable_field = "variables" if static else "inputs"
        variables = agent.variables if static else agent.inputs
        if not variables:
            self.report(("game", "agents", i, variable_field), f"agent {agent.name!r} has no {variable_field}")
        for vname, var in variables.items():
            path = ("game", "agents", i, variable_field, vname)
            self.declare(vname, path, "variable" if static else "input", key=True)
            lo = var.lower if var.lower is not None else -math.inf
            hi = var.upper if var.upper is not None else math.inf
            starts = var.start if isinstance(var.start, list) else [var.start]
            if isinstance(var.start, list) and static:
                self.report(path + ("start",), "a variable's start is one number (lists over stages are for inputs)")
            elif isinstance(var.start, list) and len(var.start) != g.horizon + 1:
                self.report(path + ("start",), f"has {len(var.start)} entries for the {g.horizon + 1} stages 0..T")
            if math.isnan(lo) or math.isnan(hi) or not all(math.isfinite(v) for v in starts):
                self.report(path, "bounds and start must be numbers (start finite)")
            elif lo > hi:
                self.report(path, f"lower bound {lo} exceeds upper bound {hi}")

    # runtime parameters ----------------------------------------------------------------------------
    def runtime(self) -> None:
        """Runtime parameters: names, values of a consistent shape, data files that can be read and cover the run."""
        g = self.g
        reported = len(self.problems)
        for name, spec in g.runtime.items():
            path = ("game", "runtime", name)
            self.declare(name, path, "runtime parameter", key=True)
            if self.static and (spec.per_stage or spec.file is not None):
                self.report(path, "a static game has no stages or time: a runtime parameter here is a number, "
                                  "a vector or a matrix")
                continue
            if spec.file is not None:
                if spec.value is not None or spec.per_stage:
                    self.report(path, "a data file gives the values at every stage: leave out value and per_stage")
                self._table(name, spec, path)
                self.kinds[name] = "stages"
                continue
            kind = self._runtime_value(spec, path)
            if kind is not None:
                self.kinds[name] = kind
        self.runtime_ok = len(self.problems) == reported  # the layout can be built (the entries' checks need it)

    def _runtime_value(self, spec: Any, path: PathKey) -> str | None:
        value = spec.value
        if spec.per_stage:
            if isinstance(value, list):
                n = self.g.horizon + 1
                if any(isinstance(v, list) for v in value) or len(value) not in (n, n + 1):
                    self.report(path + ("value",), f"a per-stage value is one number or a list of {n} (stages 0..T) "
                                                   f"or {n + 1} numbers (and the terminal cost's T + 1)")
                    return None
            return "stages"
        if isinstance(value, list):
            if not value:
                self.report(path + ("value",), "is empty")
                return None
            if isinstance(value[0], list):
                if any(len(row) != len(value[0]) for row in value) or not value[0]:
                    self.report(path + ("value",), "a matrix's rows must have the same number of entries")
                    return None
                return "matrix"
            return "vector"
        return "scalar"

    def _table(self, name: str, spec: Any, path: PathKey) -> None:
        try:
            table = read_table(data_path(self.cfg.source, spec.file), spec.column if spec.column is not None else name,
                               spec.time, spec.interpolation)
        except TableError as e:
            self.report(path + ("file",), str(e))
            return
        self.cfg.__dict__.setdefault("_runtime_tables", {})[name] = table
        start, end = needed_span(self.cfg)
        if table.times[0] > start or table.times[-1] < end - 1e-9 * max(1.0, abs(end)):
            cfg = self.cfg
            self.report(path + ("file",), f"{spec.file}: the table spans t = {table.times[0]:g} .. "
                                          f"{table.times[-1]:g} s; the run needs t = {start:g} .. {end:g} s "
                                          f"(run.steps = {cfg.run.steps} sampling times of "
                                          f"{cfg.run.sampling_time:g} s, "
                                          f"the last one looking {self.g.horizon + 1} stages ahead)")

    def indices(self, parsed: Expression | Constraint, path: PathKey, taus: list[int] | None) -> None:
        """The runtime parameters' entries in one expression: each names a vector, matrix or per-stage table with
        as many indices as it has, every index an exact integer in its range at every stage ``taus`` it is used at
        (None: no stage index here); a vector or matrix is never used without its indices."""
        roots = [parsed.tree] if isinstance(parsed, Expression) else [parsed.lhs, parsed.rhs]
        stack = list(roots)
        found: list[Index] = []
        while stack:
            n = stack.pop()
            if isinstance(n, Index):
                found.append(n)
            elif isinstance(n, Name) and self.kinds.get(n.id) in ("vector", "matrix"):  # scalars, stages: by name
                self.report(path, f"{n.id!r} is a runtime {self.kinds[n.id]}: use its entries ({n.id}[1]"
                                  f"{'[1]' if self.kinds[n.id] == 'matrix' else ''})", column=n.column,
                            text=parsed.text)
                return
            stack.extend(children(n))
        if not found:
            return
        layout = runtime_layout(self.cfg)
        ints = {k: v for k, v in self.g.parameters.items() if float(v).is_integer()}
        fns = numpy_functions()
        for node in found:
            if self.kinds.get(node.name, "scalar") == "scalar":
                what = "a runtime number" if node.name in self.g.runtime else "not a runtime parameter"
                self.report(path, f"{node.name!r} is indexed but is {what} (indexed here: runtime vectors, matrices "
                                  "and per-stage parameters)", column=node.column, text=parsed.text)
                return
            entry = layout.entries[node.name]
            table = SymbolTable(entry, list(range(entry.size)))
            staged = taus is not None and "tau" in names_in(node)  # an index of tau: checked at every stage
            for tau in (taus if staged else [None]):
                env = dict(ints) if tau is None else {**ints, "tau": float(tau)}
                env[node.name + "[]"] = table
                try:
                    evaluate(node, env, fns)
                except KeyError as e:
                    self.report(path, f"{e.args[0]!r} in an index of {node.name!r} is not an integer parameter or "
                                      "tau", column=node.column, text=parsed.text)
                    return
                except ValueError as e:
                    self.report(path, f"{e}" + (f" (at tau = {tau})" if tau is not None else ""), column=node.column,
                                text=parsed.text)
                    return

    # expressions ------------------------------------------------------------------------------------
    def check(self, text: StageConstraint | SharedSpec, path: PathKey, names: set[str], constraint: bool,
              taus: list[int] | None = None) -> None:
        """One expression or constraint (with its stages and agents): it parses and uses only ``names``; its runtime
        parameters' entries are checked at the stages ``taus``."""
        g = self.g
        if not isinstance(text, str):
            if taus is not None and text.stages is not None:
                taus = [t for t in text.stages if 0 <= t <= g.horizon]
            if text.stages is not None and self.static:
                self.report(path + ("stages",), "a static game has no stages")
            elif text.stages is not None:
                bad = [t for t in text.stages if not 0 <= t <= g.horizon]
                if bad:
                    self.report(path + ("stages",), f"stage {bad[0]} is outside 0..T = 0..{g.horizon}")
            for name in getattr(text, "agents", None) or []:
                if name not in self.agent_names:
                    self.report(path + ("agents",), f"{name!r} is not an agent (agents: "
                                                    f"{', '.join(a.name for a in g.agents)})")
            carriers = getattr(text, "agents", None) or []
            if len(set(carriers)) != len(carriers):
                self.report(path + ("agents",), "names an agent twice")
            text, path = text.expr, path + ("expr",)
        try:
            parsed = parse_constraint(text) if constraint else parse_expression(text)
            check_names(parsed, names)
            roots = [parsed.lhs, parsed.rhs] if constraint else [parsed.tree]
            integer = next((n for root in roots for n in nodes(root) if isinstance(n, Binary)
                            and n.op in INTEGER_OPERATORS), None) if "%" in text or "//" in text else None
            if integer is not None:  # the expansion writes out those of integers (gnerun.language.substitute)
                raise ExpressionError(f"'{integer.op}' is integer arithmetic (indices, integer parameters, T): "
                                      f"{unparse(integer)!r} is not", text, integer.column)
        except ExpressionError as e:
            if e.whole:  # its length as written out: no column of it to show
                self.report(path, e.message + " as the game uses it (its sums, products and definitions written out)")
            else:
                self.report(path, e.message, column=e.column, text=text)
            return
        if g.runtime and self.runtime_ok:
            self.indices(parsed, path, taus)

    def expressions(self) -> None:
        """Costs, constraints, x0 and dynamics, and the shared constraints."""
        g, static = self.g, self.static
        params = set(g.parameters) | set(g.runtime)
        if not static:
            params.add("t")  # the absolute time of a stage (no declared name is t: declare)
        decisions = {v for a in g.agents for v in (a.variables if static else a.inputs)}
        if static:
            scope = decisions | params
            for i, agent in enumerate(g.agents):
                self.check(agent.cost, ("game", "agents", i, "cost"), scope, False)
                for j, c in enumerate(agent.constraints):
                    self.check(c, ("game", "agents", i, "constraints", j), scope, True)
        else:
            states = set(g.states)
            if self.ode:  # dt: the sampling time, dynamics.dt (or the parameter dt, which must equal it)
                params = params | {"dt"}
            scope = states | decisions | params | {"tau"}  # tau: the stage index, 0..T
            taus = list(range(g.horizon + 1))
            for i, agent in enumerate(g.agents):
                self.check(agent.stage_cost, ("game", "agents", i, "stage_cost"), scope, False, taus)
                self.check(agent.terminal_cost, ("game", "agents", i, "terminal_cost"), states | params, False)
                for j, c in enumerate(agent.constraints):
                    self.check(c, ("game", "agents", i, "constraints", j), scope, True, taus)
            runtime = {n for n, what in self.seen.items() if what == "runtime parameter"}
            self._dynamics(scope - runtime - {"t"})
        for j, c in enumerate(g.shared_constraints):
            self.check(c, ("game", "shared_constraints", j), scope, True, None if static else taus)
        if not static:
            for state, text in g.references.items():
                if state not in g.states:
                    self.report(("game", "references", state), f"{state!r} is not a state (states: "
                                f"{', '.join(g.states)})", key=True)
                else:  # what the plant's state is compared with: no decision, no state, no stage
                    self.check(text, ("game", "references", state), params, False)

    def _dynamics(self, scope: set[str]) -> None:
        """x0 and the dynamics of a dynamic game: shapes, finite numbers, one equation per state."""
        g = self.g
        inputs = [u for a in g.agents for u in a.inputs]
        nx, nu = len(g.states), len(inputs)
        if len(g.x0) != nx:
            self.report(("game", "x0"), f"has {len(g.x0)} entries for {nx} states")
        elif not all(math.isfinite(v) for v in g.x0):
            self.report(("game", "x0"), "must be finite")
        if isinstance(g.dynamics, LinearDynamics):
            A, B = g.dynamics.A, g.dynamics.B
            if len(A) != nx or any(len(r) != nx for r in A):
                self.report(("game", "dynamics", "A"), f"must be {nx} x {nx} (states {', '.join(g.states)})")
            if len(B) != nx or any(len(r) != nu for r in B):
                self.report(("game", "dynamics", "B"),
                            f"must be {nx} x {nu} (inputs in agent order: {', '.join(inputs)})")
            if not all(math.isfinite(v) for row in A + B for v in row):
                self.report(("game", "dynamics"), "A and B must be finite")
            return
        if self.ode and "dt" in g.parameters and g.parameters["dt"] != g.dynamics.dt:
            self.report(("game", "dynamics", "dt"), f"is {g.dynamics.dt!r}, but the parameter dt is "
                        f"{g.parameters['dt']!r} ({self.smap.locate(('game', 'parameters', 'dt'))}): in a game with "
                        "an ode, dt names the sampling time; make the two equal, or leave the parameter out")
        equations, where = (g.dynamics.ode, ("game", "dynamics", "ode")) if isinstance(
            g.dynamics, ContinuousDynamics) else (g.dynamics, ("game", "dynamics"))
        for s in g.states:
            if s not in equations:
                self.report(where, f"no equation for state {s!r}")
        for s, text in equations.items():
            if s not in g.states:
                self.report(where + (s,), f"{s!r} is not a declared state (states: {', '.join(g.states)})", key=True)
            else:  # the dynamics are the same at every stage (no tau)
                declared = {n for n, what in self.seen.items() if what == "runtime parameter"}
                runtime = sorted(_names_of(text) & (declared | {"t"}))
                if runtime:
                    self.report(where + (s,), f"{runtime[0]!r} is a runtime value: the dynamics are compiled with "
                                              "constants (parameters), the same at every stage and sampling time")
                    continue
                self.check(text, where + (s,), scope - {"tau"}, False)

    # the other sections -----------------------------------------------------------------------------
    def disturbance(self) -> None:
        """The plant disturbance's scale and kind."""
        plant = self.cfg.disturbance.plant
        scales = plant.scale if isinstance(plant.scale, list) else [plant.scale]
        if not all(math.isfinite(v) for v in scales) or (plant.kind != "constant" and any(v < 0 for v in scales)):
            self.report(("disturbance", "plant", "scale"),
                        "must be finite" + (" and >= 0" if plant.kind != "constant" else ""))
        if isinstance(plant.scale, list):
            nx = 0 if self.static else len(self.g.states)
            if len(plant.scale) != nx:
                self.report(("disturbance", "plant", "scale"), f"has {len(plant.scale)} entries for {nx} states")
        if plant.kind != "none" and self.static:
            self.report(("disturbance", "plant", "kind"), "a static game has no plant")

    def solver(self) -> None:
        """The solver's options that go together (with each other and with the disturbance)."""
        cfg = self.cfg
        if cfg.disturbance.kind == "pseudogradient" and cfg.solver.kind == "ssn":
            self.report(("disturbance", "kind"), "'pseudogradient' perturbs the Josephy-Newton method; with "
                        "solver.kind 'ssn' use 'jacobian_noise' or 'residual'")
        if cfg.solver.formulation == "sparse":
            why = sparse_obstacles(cfg)
            if why:
                self.report(("solver", "formulation"), "'sparse' is not available here: " + "; ".join(why)
                            + " (use 'condensed' or 'auto')")
        if cfg.solver.kind == "jn" and cfg.solver.globalization not in ("auto", "none"):
            self.report(("solver", "globalization"), f"{cfg.solver.globalization!r} globalizes semismooth Newton; "
                        "Josephy-Newton solves each step's affine VI exactly (use auto or none, or solver.kind 'ssn')")
        if cfg.disturbance.kind in ("jacobian_noise", "residual") and cfg.solver.kind == "jn":
            self.report(("disturbance", "kind"), f"{cfg.disturbance.kind!r} perturbs semismooth Newton; with "
                        "solver.kind 'jn' use 'pseudogradient' (noise on F and H)")

    def sampling_time(self) -> None:
        """The closed loop's sampling time: one the run log can count, and the ode's dt."""
        cfg = self.cfg
        dynamics = getattr(self.g, "dynamics", None)
        if not self.static:  # a closed loop's log time is t x sampling_time in nanoseconds, an unsigned 64-bit integer
            given = ("run", "sampling_time") if self.smap.has(("run", "sampling_time")) or not isinstance(
                dynamics, ContinuousDynamics) else ("game", "dynamics", "dt")
            ts, end = cfg.run.sampling_time, cfg.run.steps * cfg.run.sampling_time
            if ts < MIN_SAMPLING_TIME:
                self.report(given, f"is {ts:g} s, below the log's resolution of one nanosecond (every sampling time "
                                   "would be logged at the same time)")
            elif end > MAX_LOG_SECONDS:
                self.report(given, f"is {ts:g} s: run.steps = {cfg.run.steps:,} sampling times of it span "
                                   f"{end:.3g} s, beyond the {MAX_LOG_SECONDS:.3g} s (about "
                                   f"{MAX_LOG_SECONDS / 3.156e7:,.0f} years) a run log's time in nanoseconds can count")
        if isinstance(dynamics, ContinuousDynamics) and cfg.run.sampling_time != dynamics.dt:
            self.report(("run", "sampling_time"), f"is {cfg.run.sampling_time:g} s, but the ode is integrated over "
                        f"one sampling time of dynamics.dt = {dynamics.dt:g} s (leave it out, or make the two equal)")
