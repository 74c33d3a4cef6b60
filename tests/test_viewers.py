"""Run logs in clients written elsewhere: the JSON Schema that Foxglove and Lichtblick read, independent readers
(the mcap package's plain reader with jsonschema; the official TypeScript reader @mcap/core with ajv), the
foxglove.Log topic and the time axis a Plot panel shows. Logs of an earlier version still read everywhere."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import jsonschema
import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader

from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_run, recover
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import solve

from .conftest import CONFIGS, run_cli

TESTS = Path(__file__).resolve().parent
OLD_LOGS = TESTS / "data" / "logs-0.1.0"  # written by gnerun 0.1.0 before its schemas were the viewers' subset
READER_JS = TESTS / "js" / "read_mcap.cjs"


# -------------------------------------------------------------------------------------------------
# What the viewers parse
# -------------------------------------------------------------------------------------------------


class ViewerRejects(Exception):
    pass


def viewer_datatypes(schema: dict, name: str) -> dict[str, list[tuple[str, str, bool]]]:
    """The message definitions that Lichtblick (and Foxglove Studio, whose JSON Schema channel parser it
    inherits) make of a ``jsonschema`` channel, or ViewerRejects with the viewer's message.

    Written from the documented behaviour of their parser (packages/mcap-support, parseJsonSchema): the root and
    every nested object must have ``"type": "object"`` and ``properties``; a field is read by its ``type`` alone:
    boolean, string (``contentEncoding`` none or base64), number or integer (both float64), object (recursively)
    or array, whose ``items`` must have one of those types. A field whose property has ``oneOf`` is an enum when
    every alternative is a numeric ``const`` (foxglove.Log's level), otherwise refused; ``anyOf`` is not read, so
    such a field has no type. "null", a list of types and a missing type are refused."""
    out: dict[str, list[tuple[str, str, bool]]] = {}

    def walk(node: dict, type_name: str, path: list[str]) -> None:
        if node.get("type") != "object":
            raise ViewerRejects(f'Expected "type": "object" for schema {type_name}, got {json.dumps(node.get("type"))}')
        properties = node.get("properties")
        if not isinstance(properties, dict):
            raise ViewerRejects(f"{type_name}: Cannot convert undefined or null to object")
        fields = []
        for field, sub in properties.items():
            where = ".".join([*path, field])
            if isinstance(sub.get("oneOf"), list):
                if all(isinstance(alt.get("const"), int | float) for alt in sub["oneOf"]):
                    fields.append((field, "uint32", False))
                    continue
                raise ViewerRejects(f"Unsupported type for {where}: oneOf alternatives must have number values")
            kind = sub.get("type")
            if kind == "boolean":
                fields.append((field, "bool", False))
            elif kind == "string":
                if sub.get("contentEncoding") not in (None, "base64"):
                    raise ViewerRejects(f"Unsupported contentEncoding {json.dumps(sub['contentEncoding'])} in {where}")
                fields.append((field, "uint8" if sub.get("contentEncoding") else "string", bool(sub.get(
                    "contentEncoding"))))
            elif kind in ("number", "integer"):
                fields.append((field, "float64", False))
            elif kind == "object":
                walk(sub, f"{type_name}.{field}", [*path, field])
                fields.append((field, f"{type_name}.{field}", False))
            elif kind == "array":
                items = sub.get("items") or {}
                item = items.get("type")
                if item in ("number", "integer"):
                    fields.append((field, "float64", True))
                elif item in ("boolean", "string") and "contentEncoding" not in items:
                    fields.append((field, "bool" if item == "boolean" else "string", True))
                elif item == "object":
                    walk(items, f"{type_name}.{field}", [*path, field])
                    fields.append((field, f"{type_name}.{field}", True))
                else:
                    shown = "undefined" if item is None else json.dumps(item)
                    raise ViewerRejects(f"Unsupported type {shown} for array item {where}")
            else:  # "null", ["number", "null"], or no type at all (anyOf)
                shown = "undefined" if kind is None else json.dumps(kind, separators=(",", ":"))
                raise ViewerRejects(f"Unsupported type {shown} for {where}")
        out[type_name] = fields

    walk(schema, name, [])
    return out


def resolve(datatypes: dict, root: str, path: str) -> tuple[str, bool]:
    """The type of a message path such as ``.e_norm_agent.agent1`` or ``.x[0]`` (Plot panel syntax)."""
    type_name, is_array = root, False
    for part in path.lstrip(".").split("."):
        index = part.endswith("]")
        name = part.split("[")[0]
        fields = {f: (t, a) for f, t, a in datatypes[type_name]}
        assert name in fields, f"{path}: no field {name!r} in {type_name} ({sorted(fields)})"
        type_name, is_array = fields[name]
        if index:
            assert is_array, f"{path}: {name} is not an array"
            is_array = False
    return type_name, is_array


def test_the_viewer_subset_refuses_what_the_viewers_refuse() -> None:
    nullable = {"type": "object", "properties": {"e_norm": {"anyOf": [{"type": "number"}, {"type": "null"}]}}}
    cases = [
        (nullable, "Unsupported type undefined for e_norm"),  # the viewers' message for logs of earlier versions
        ({"type": "object", "properties": {"e": {"type": ["number", "null"]}}}, 'Unsupported type ["number","null"]'),
        ({"type": "object", "properties": {"e": {"type": "null"}}}, 'Unsupported type "null"'),
        ({"type": "object", "properties": {"a": {"type": "object", "additionalProperties": {"type": "number"}}}},
         "Cannot convert undefined"),  # a mapping without named properties
        ({"type": "object", "properties": {"x": {"type": "array", "items": {"anyOf": [{"type": "number"}]}}}},
         "Unsupported type undefined for array item x"),
        ({"type": "object", "properties": {"l": {"oneOf": [{"const": "a"}]}}}, "oneOf alternatives must have"),
    ]
    for schema, message in cases:
        with pytest.raises(ViewerRejects, match=message.replace("[", r"\[").replace("]", r"\]")):
            viewer_datatypes(schema, "X")
    assert viewer_datatypes({"type": "object", "properties": {"x": {"type": "array", "items": {"type": "number"}},
                                                              "k": {"type": "integer"}}}, "X") == {
        "X": [("x", "float64", True), ("k", "float64", False)]}


# -------------------------------------------------------------------------------------------------
# Logs of this version: a solve, a closed loop, a distributed closed loop, a killed and a recovered one
# -------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("logs")
    solve(load_config(CONFIGS / "paper_study1.yaml"), out=root / "solve")
    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 6, "run.K": [1, 3],
                                                         "run.sampling_time": 0.25}), out=root / "simulate")
    simulate(load_config(CONFIGS / "paper_study3.yaml", {"run.steps": 4}), out=root / "distributed")
    data = (root / "simulate" / "run.mcap").read_bytes()
    (root / "killed").mkdir()
    (root / "killed" / "run.mcap").write_bytes(data[: int(len(data) * 0.6)])
    (root / "recovered").mkdir()
    recover(root / "killed" / "run.mcap", root / "recovered" / "run.mcap")
    return {"solve": root / "solve", "simulate": root / "simulate", "distributed": root / "distributed",
            "killed": root / "killed", "recovered": root / "recovered"}


def plain_read(path: Path) -> tuple[list[tuple[Schema, Channel, Message]], bool]:
    """Every message of a log with the mcap package's own readers: through the index when there is one, else
    record by record (a killed run). Returns the messages and whether the index was used."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        try:
            if reader.get_summary() is not None:
                return list(reader.iter_messages(log_time_order=True)), True
        except Exception:  # noqa: BLE001 - no usable summary: read the records instead
            pass
    schemas, channels, out = {}, {}, []
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    channel = channels[record.channel_id]
                    out.append((schemas[channel.schema_id], channel, record))
        except Exception:  # noqa: BLE001 - the truncated last record
            pass
    return out, False


KINDS = ["solve", "simulate", "distributed", "killed", "recovered"]


@pytest.mark.parametrize("kind", KINDS)
def test_every_schema_is_in_the_viewer_subset(logs, kind) -> None:
    messages, _ = plain_read(logs[kind] / "run.mcap")
    schemas = {channel.topic: schema for schema, channel, _ in messages}
    assert schemas
    for topic, schema in schemas.items():
        assert schema.encoding == "jsonschema"
        parsed = json.loads(schema.data)
        viewer_datatypes(parsed, schema.name)  # raises what the viewer would say
        text = json.dumps(parsed)
        assert "anyOf" not in text and "$ref" not in text and '"null"' not in text, topic
        if topic != "/log":
            assert "oneOf" not in text, topic


@pytest.mark.parametrize("kind", KINDS)
def test_every_message_is_valid_against_its_channel_schema(logs, kind) -> None:
    """The mcap package's plain reader and jsonschema, not gnerun's reader."""
    messages, indexed = plain_read(logs[kind] / "run.mcap")
    assert indexed == (kind != "killed")
    validators = {}
    for schema, channel, message in messages:
        assert channel.message_encoding == "json"
        if schema.id not in validators:
            parsed = json.loads(schema.data)
            jsonschema.Draft202012Validator.check_schema(parsed)
            validators[schema.id] = jsonschema.Draft202012Validator(parsed)
        validators[schema.id].validate(json.loads(message.data))
    assert len(messages) == read_run(logs[kind]).message_count


def test_the_logged_values_are_the_summary_values(logs) -> None:
    """Read back with the plain reader, the closed loop's messages hold what summary.json holds."""
    messages, _ = plain_read(logs["distributed"] / "run.mcap")
    summary = json.loads((logs["distributed"] / "summary.json").read_text())
    for K in (2, 5):
        by_K = summary["by_K"][str(K)]
        errors = [json.loads(m.data) for _, c, m in messages if c.topic == f"/K{K}/mpc/error"]
        assert [e["t"] for e in errors] == list(range(len(by_K["e_norm"])))
        assert [e.get("e_norm") for e in errors] == by_K["e_norm"]
        for agent, values in by_K["e_norm_agent"].items():
            assert [e["e_norm_agent"].get(agent) for e in errors] == values
        states = [json.loads(m.data) for _, c, m in messages if c.topic == f"/K{K}/mpc/state"]
        assert [s["x"] for s in states] == by_K["x"]
        assert [s["u"] for s in states[:-1]] == by_K["u"] and "u" not in states[-1]  # the last state ends the loop


def test_per_agent_errors_and_states_are_plottable_paths(logs) -> None:
    messages, _ = plain_read(logs["distributed"] / "run.mcap")
    channels = {c.topic: s for s, c, _ in messages}
    for topic, path, expected in [("/K5/mpc/error", ".e_norm_agent.agent1", ("float64", False)),
                                  ("/K5/mpc/error", ".e_norm", ("float64", False)),
                                  ("/K5/mpc/state", ".x[2]", ("float64", False)),
                                  ("/K5/mpc/iterate", ".residual_norm", ("float64", False))]:
        schema = channels[topic]
        assert resolve(viewer_datatypes(json.loads(schema.data), schema.name), schema.name, path) == expected
    solve_messages, _ = plain_read(logs["solve"] / "run.mcap")
    schema = next(s for s, c, _ in solve_messages if c.topic == "/solve/iterate")
    assert resolve(viewer_datatypes(json.loads(schema.data), schema.name), schema.name, ".error_norm") == (
        "float64", False)


def test_a_missing_value_is_left_out_and_the_message_stays_valid(tmp_path) -> None:
    sim = simulate(load_config(CONFIGS / "paper_study3.yaml", {"run.steps": 2, "run.K": [2],
                                                               "run.reference": "none"}), out=tmp_path / "run")
    assert all(v != v for v in sim[2].e_norm)  # no z*: no error
    messages, _ = plain_read(tmp_path / "run" / "run.mcap")
    errors = [(s, json.loads(m.data)) for s, c, m in messages if c.topic == "/K2/mpc/error"]
    assert errors and all(e == {"t": e["t"], "e_norm_agent": {}} for _, e in errors)
    for schema, e in errors:
        jsonschema.validate(e, json.loads(schema.data))
    assert not any(b"null" in m.data for _, _, m in messages)


def test_log_is_the_well_known_foxglove_log(logs) -> None:
    for kind in ("solve", "simulate", "distributed"):
        messages, _ = plain_read(logs[kind] / "run.mcap")
        entries = [(s, m) for s, c, m in messages if c.topic == "/log"]
        assert entries
        schema = json.loads(entries[0][0].data)
        assert entries[0][0].name == "foxglove.Log"
        # the published schema (foxglove/schemas, schemas/jsonschema/Log.json): these fields, these types
        props = schema["properties"]
        assert set(props) == {"timestamp", "level", "message", "name", "file", "line"}
        assert props["timestamp"]["type"] == "object" and set(props["timestamp"]["properties"]) == {"sec", "nsec"}
        assert [(a["title"], a["const"]) for a in props["level"]["oneOf"]] == [
            ("UNKNOWN", 0), ("DEBUG", 1), ("INFO", 2), ("WARNING", 3), ("ERROR", 4), ("FATAL", 5)]
        assert [props[k]["type"] for k in ("message", "name", "file", "line")] == ["string", "string", "string",
                                                                                   "integer"]
        for _, m in entries:
            entry = json.loads(m.data)
            assert entry["timestamp"]["sec"] * 10**9 + entry["timestamp"]["nsec"] == m.log_time
            assert entry["level"] in (1, 2, 3, 4) and entry["message"] and entry["name"] == "gnerun"


def test_log_time_is_the_runs_own_time(logs) -> None:
    sampling_time = 0.25  # the fixture's run.sampling_time
    messages, _ = plain_read(logs["simulate"] / "run.mcap")
    for _, channel, m in messages:
        if channel.topic.startswith("/K"):
            assert m.log_time == round(json.loads(m.data)["t"] * sampling_time * 1e9), channel.topic
    steps = 6
    log_times = [m.log_time for _, c, m in messages if c.topic == "/log"]
    assert min(log_times) == 0 and max(log_times) == steps * sampling_time * 1e9
    # what a viewer's time axis spans: the loop's own 1.5 s, not the wall clock
    with open(logs["simulate"] / "run.mcap", "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert (stats.message_start_time, stats.message_end_time) == (0, steps * sampling_time * 1e9)
    # a solve's time axis is its iteration count: iterate k at k seconds, the last status with the last iterate
    solve = plain_read(logs["solve"] / "run.mcap")[0]
    for _, channel, m in solve:
        if channel.topic == "/solve/iterate":
            assert m.log_time == json.loads(m.data)["k"] * 10**9
    iterations = json.loads((logs["solve"] / "summary.json").read_text())["iterations"]
    assert [m.log_time for _, c, m in solve if c.topic == "/log"][-1] == iterations * 10**9


def test_the_sampling_time_of_an_ode_is_its_dt(tmp_path) -> None:
    cfg = load_config(CONFIGS / "mcp_demo.yaml")
    assert cfg.run.sampling_time == cfg.game.dynamics.dt
    assert load_config(CONFIGS / "paper_study2.yaml").run.sampling_time == 1.0  # discrete time: 1 s per step


# -------------------------------------------------------------------------------------------------
# The official TypeScript reader
# -------------------------------------------------------------------------------------------------


def _node_env() -> dict[str, str] | None:
    """An environment in which node finds @mcap/core, ajv and fzstd (tests/js/node_modules, from
    `npm install --prefix tests/js`, or GNERUN_NODE_MODULES), or None."""
    node = shutil.which("node")
    if node is None:
        return None
    env = dict(os.environ)
    if os.environ.get("GNERUN_NODE_MODULES"):
        env["NODE_PATH"] = os.environ["GNERUN_NODE_MODULES"]
    probe = subprocess.run([node, "-e", "require('@mcap/core'); require('ajv'); require('fzstd')"],
                           cwd=READER_JS.parent, env=env, capture_output=True, timeout=60)
    return env if probe.returncode == 0 else None


NODE_ENV = _node_env()


@pytest.mark.skipif(NODE_ENV is None, reason="needs node with @mcap/core, ajv and fzstd "
                                             "(npm install --prefix tests/js)")
@pytest.mark.parametrize("kind", KINDS)
def test_the_typescript_reader_reads_and_validates_every_message(logs, kind) -> None:
    proc = subprocess.run(["node", str(READER_JS), str(logs[kind] / "run.mcap")], capture_output=True, text=True,
                          env=NODE_ENV, timeout=120)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["reader"] == ("McapStreamReader" if kind == "killed" else "McapIndexedReader")
    assert result["invalid"] == []
    record = read_run(logs[kind])
    assert result["topics"] == {topic: len(msgs) for topic, msgs in record.messages.items()}
    assert result["schemas"]["/log"] == "foxglove.Log"


# -------------------------------------------------------------------------------------------------
# Logs of an earlier version
# -------------------------------------------------------------------------------------------------


def test_logs_of_an_earlier_version_read_in_inspect_figures_and_replay(tmp_path) -> None:
    for kind in ("solve", "simulate", "distributed"):
        run = OLD_LOGS / kind
        schemas = {c.topic: json.loads(s.data) for s, c, _ in plain_read(run / "run.mcap")[0]}
        if kind != "solve":  # what the viewers refused: nullable fields as anyOf
            with pytest.raises(ViewerRejects, match="Unsupported type undefined"):
                viewer_datatypes(schemas["/K2/mpc/error" if kind == "distributed" else "/K1/mpc/error"], "X")
        proc = run_cli("inspect", str(run))
        assert proc.returncode == 0, proc.stderr
        assert "finished log" in proc.stdout and "time range: 20" in proc.stdout  # the wall clock of the time
    proc = run_cli("figures", *(str(OLD_LOGS / k) for k in ("solve", "simulate", "distributed")), "--out",
                   str(tmp_path / "f"), "--format", "png")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "f").iterdir()) == [
        "paper-study1-study1.png", "paper-study2-study2.png", "paper-study3-study3.png"]
    proc = run_cli("replay", *(str(OLD_LOGS / k) for k in ("solve", "simulate", "distributed")), "--save",
                   str(tmp_path / "old.rrd"))
    assert proc.returncode == 0, proc.stderr and (tmp_path / "old.rrd").stat().st_size > 0


def test_recover_turns_an_earlier_log_into_one_the_viewers_open(tmp_path) -> None:
    old = read_run(OLD_LOGS / "simulate")
    target = tmp_path / "run.mcap"
    proc = run_cli("recover", str(OLD_LOGS / "simulate"), "--out", str(target))
    assert proc.returncode == 0, proc.stderr
    messages, _ = plain_read(target)
    for schema, _, message in messages:
        viewer_datatypes(json.loads(schema.data), schema.name)
        jsonschema.validate(json.loads(message.data), json.loads(schema.data))
    new = read_run(target)
    assert new.log_times == old.log_times
    assert [m["message"] for m in new.messages["/log"]] == [m["message"] for m in old.messages["/log"]]
    assert [m["level"] for m in new.messages["/log"]] == [{"info": 2, "warning": 3}[m["level"]]
                                                         for m in old.messages["/log"]]
    for topic, msgs in old.messages.items():  # the data as they were, nulls now left out
        if topic != "/log":
            assert new.messages[topic] == [{k: v for k, v in m.items() if v is not None} for m in msgs], topic
