"""Rerun recordings built from run logs, read back with rerun's own reader."""

from __future__ import annotations

import contextlib
import math
import os
import select
import signal
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_run
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import solve
from gnerun.view.figures import FLOOR
from gnerun.view.replay import EDGE_COLOUR, PALETTE, TRAIL_BLOCK, _lighter, save, serve_command, vulkan_available

from .conftest import CONFIGS, gnerun_command, run_cli


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("runs")
    out = {"solve": root / "s1", "loop": root / "s2", "dist": root / "s3", "merge": root / "s4"}
    solve(load_config(CONFIGS / "paper_study1_disturbed.yaml"), out=out["solve"])
    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 8, "run.K": [1, 3]}), out=out["loop"])
    simulate(load_config(CONFIGS / "paper_study3.yaml", {"run.steps": 6}), out=out["dist"])
    simulate(load_config(CONFIGS / "algames_merge_mpc.yaml", {"run.steps": 5, "run.K": [1, 3]}), out=out["merge"])
    return out


def _series(rrd: Path) -> dict[str, dict[str, list]]:
    """entity path -> {timeline or 'value': column} for every scalar entity of the recording."""
    out: dict[str, dict[str, list]] = {}
    for chunk in RrdReader(rrd).stream().to_chunks():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "Scalars:scalars" not in names:
            continue
        entry = out.setdefault(chunk.entity_path, {})
        for timeline in ("iteration", "t"):
            if timeline in names:
                entry.setdefault(timeline, []).extend(batch.column(timeline).to_pylist())
        entry.setdefault("value", []).extend(v[0] for v in batch.column("Scalars:scalars").to_pylist())
    return out


def _check_log10(got: dict[str, list], timeline: str, logged: list[tuple[int, float | None]]) -> float | None:
    """A figure view's series: log10 of each value at or above the floor, one row below it for the values under
    the floor (exact zeros included), nothing where a value is missing. Returns the row."""
    drawn = dict(zip(got[timeline], got["value"], strict=True))
    rows = set()
    for at, v in logged:
        if v is None:
            assert at not in drawn
        elif v >= FLOOR:
            assert drawn[at] == pytest.approx(math.log10(v), abs=1e-12)
        else:
            assert drawn[at] < math.log10(FLOOR)
            rows.add(drawn[at])
    assert len(rows) <= 1
    return rows.pop() if rows else None


def test_recording_holds_the_logged_values(runs, tmp_path: Path) -> None:
    rrd = save([runs["solve"], runs["loop"], runs["dist"]], tmp_path / "all.rrd")
    reader = RrdReader(rrd)
    assert [r.kind for r in reader.recordings()] == ["recording"]
    assert len(reader.blueprints()) == 1  # the figure layout travels with the recording
    series = _series(rrd)
    # Fig. 1: ||z^k - z*|| and its log10 on the iteration timeline
    iterates = read_run(runs["solve"]).messages["/solve/iterate"]
    s = series["/paper-study1-disturbed/solve/error_norm"]
    assert s["iteration"] == [m["k"] for m in iterates]
    assert s["value"] == [m["error_norm"] for m in iterates]
    _check_log10(series["/paper-study1-disturbed/solve/log10_error_norm"], "iteration",
                 [(m["k"], m.get("error_norm")) for m in iterates])
    # Fig. 2: x(t) per state and e(t) per K on the t timeline
    loop = read_run(runs["loop"])
    for K in (1, 3):
        states = loop.messages[f"/K{K}/mpc/state"]
        for j, name in enumerate(("x1", "x2", "x3")):
            x = series[f"/paper-study2/K{K}/x/{name}"]
            assert x["t"] == [m["t"] for m in states] and x["value"] == [m["x"][j] for m in states]
        u = series[f"/paper-study2/K{K}/u/u2"]
        assert u["value"] == [m["u"][1] for m in states if "u" in m]
        errors = loop.messages[f"/K{K}/mpc/error"]
        assert series[f"/paper-study2/K{K}/e_norm"]["value"] == [m["e_norm"] for m in errors]
        _check_log10(series[f"/paper-study2/K{K}/log10_e_norm"], "t", [(m["t"], m.get("e_norm")) for m in errors])
    # Fig. 3: per-agent errors of the distributed run
    dist = read_run(runs["dist"])
    for K in (2, 5):
        errors = dist.messages[f"/K{K}/mpc/error"]
        for agent in ("agent1", "agent2", "agent3"):
            got = series[f"/paper-study3/K{K}/e_agent/{agent}"]
            assert got["value"] == [m["e_norm_agent"][agent] for m in errors]


def test_log_and_config_are_in_the_recording(runs, tmp_path: Path) -> None:
    rrd = save([runs["loop"]], tmp_path / "loop.rrd")
    texts, logs = {}, []
    for chunk in RrdReader(rrd).stream().to_chunks():
        batch = chunk.to_record_batch()
        if "TextDocument:text" in batch.schema.names:
            texts[chunk.entity_path] = batch.column("TextDocument:text").to_pylist()[0][0]
        if "TextLog:text" in batch.schema.names:
            logs += [v[0] for v in batch.column("TextLog:text").to_pylist()]
    assert texts["/paper-study2/config"] == (runs["loop"] / "config.yaml").read_text()
    assert logs == [m["message"] for m in read_run(runs["loop"]).messages["/log"]]


def test_replay_of_a_killed_run(runs, tmp_path: Path) -> None:
    data = (runs["loop"] / "run.mcap").read_bytes()
    killed = tmp_path / "killed.mcap"
    killed.write_bytes(data[: len(data) // 2])
    proc = run_cli("replay", str(killed), "--save", str(tmp_path / "killed.rrd"))
    assert proc.returncode == 0, proc.stderr
    series = _series(tmp_path / "killed.rrd")
    recovered = read_run(killed).messages["/K1/mpc/error"]
    assert 0 < len(recovered) and series["/paper-study2/K1/e_norm"]["value"] == [m["e_norm"] for m in recovered]


def test_replay_needs_an_output_without_a_display(runs) -> None:
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run([*gnerun_command(), "replay", str(runs["loop"])], capture_output=True, text=True, env=env,
                          stdin=subprocess.DEVNULL, timeout=60)
    assert proc.returncode == 2 and "--save" in proc.stderr and "Traceback" not in proc.stderr


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_serve_binds_to_localhost_only(runs, tmp_path: Path) -> None:
    web, grpc = _free_port(), _free_port()
    assert serve_command(tmp_path / "x.rrd", web, grpc)[-7:-1] == ["--bind", "127.0.0.1", "--web-viewer-port",
                                                                     str(web), "--port", str(grpc)]
    proc = subprocess.Popen([*gnerun_command(), "replay", str(runs["loop"]), "--serve", "--web-port", str(web),
                             "--grpc-port", str(grpc)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            stdin=subprocess.DEVNULL, text=True, start_new_session=True)
    try:
        # gnerun prints the URL once both of the viewer's ports answer: wait for that line, not for one port
        # (a terminate between the web port's answer and the line would leave nothing printed)
        ready, _, _ = select.select([proc.stdout], [], [], 60)
        assert ready, "the web viewer did not start"
        first = proc.stdout.readline()
        with socket.create_connection(("127.0.0.1", web), timeout=1):
            pass
        # bound to the loopback interface only: no other address of this machine answers
        others = {info[4][0] for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)}
        for address in others - {"127.0.0.1"}:
            if address.startswith("127."):
                continue
            with pytest.raises(OSError), socket.create_connection((address, web), timeout=1):
                pass
        proc.terminate()  # gnerun stops its viewer when terminated
        out, _ = proc.communicate(timeout=30)
        out = first + out
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert f"http://127.0.0.1:{web}/" in out
    time.sleep(0.5)
    with pytest.raises(OSError), socket.create_connection(("127.0.0.1", web), timeout=1):
        pass  # the viewer went down with gnerun


def _viewers_on(port: int) -> list[int]:
    """The processes whose command line serves the web viewer on ``port``."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                if f"--web-viewer-port\0{port}\0".encode() in (entry / "cmdline").read_bytes():
                    found.append(int(entry.name))
    return found


def test_a_killed_serve_takes_its_viewer_and_its_temporary_recording_with_it(runs, tmp_path: Path) -> None:
    """replay --serve killed by SIGKILL (no clean-up at all): the viewer it started (in a session of its own) gets
    SIGTERM from the kernel, and the temporary recording was removed as soon as the viewer had read it."""
    web, grpc = _free_port(), _free_port()
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = subprocess.Popen([*gnerun_command(), "replay", str(runs["loop"]), "--serve", "--web-port", str(web),
                             "--grpc-port", str(grpc)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            stdin=subprocess.DEVNULL, text=True, env=dict(os.environ, TMPDIR=str(tmp)))
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 60)
        assert ready and "web viewer:" in proc.stdout.readline(), "the web viewer did not start"
        deadline = time.monotonic() + 30
        while list(tmp.iterdir()) and time.monotonic() < deadline:  # removed once the viewer has read it
            time.sleep(0.1)
        assert not list(tmp.iterdir())
        proc.kill()
        proc.wait(30)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                with socket.create_connection(("127.0.0.1", web), timeout=1):
                    pass
            except OSError:
                break  # the viewer went down with gnerun, killed
            time.sleep(0.2)
        else:
            pytest.fail("the viewer outlived the gnerun that started it")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid in _viewers_on(web):  # a viewer left over by a failure: this test's own, by its pid
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
    assert not list(tmp.iterdir())


def _blueprint_text(rrd: Path) -> str:
    """Every string stored in the recording's blueprint (view names, container names, timelines, queries)."""
    reader = RrdReader(rrd)
    (bp,) = reader.blueprints()
    texts = []
    for chunk in reader.stream(store=bp).to_chunks():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if ":" in name:  # components (view and container names, contents queries, timelines, ranges)
                texts.append(f"{chunk.entity_path} {name} {batch.column(name).to_pylist()}")
    return "\n".join(texts)


def test_blueprint_has_one_view_per_paper_figure(runs, tmp_path: Path) -> None:
    rrd = save([runs["solve"], runs["loop"], runs["dist"]], tmp_path / "all.rrd")
    text = _blueprint_text(rrd)
    # Rerun's views have no axis titles: every view's name says what its y and x axes show
    for name in ("Fig. 1: paper-study1-disturbed (jacobian noise, scale 0.001): log10 ||z^k - z*|| (y) against "
                 "iteration k (x)",
                 "Fig. 2a: x(t) (y) against sampling time t (x), K = 3",
                 "Fig. 2b: log10 ||e(t)|| (y) against sampling time t (x), per K",
                 "Fig. 3: log10 ||e_i(t)|| (y) against sampling time t (x), paper-study3: K = 2",
                 "Fig. 3: log10 ||e_i(t)|| (y) against sampling time t (x), paper-study3: K = 5"):
        assert name in text
    assert "TimePanelBlueprint:timeline [['iteration']]" in text  # the first figure's timeline
    only_loop = _blueprint_text(save([runs["loop"]], tmp_path / "loop.rrd"))
    assert "Fig. 2a: x(t)" in only_loop and "Fig. 1" not in only_loop and "Fig. 3" not in only_loop
    assert "TimePanelBlueprint:timeline [['t']]" in only_loop
    assert "paper-study2/K3/x/x1" in only_loop and "paper-study2/K1/log10_e_norm" in only_loop


def _columns(rrd: Path, prefix: str) -> dict[str, list[tuple[int | None, object]]]:
    """entity path -> [(t, value)] of every LineStrips2D, Points2D and Clear under ``prefix`` (t None: static);
    labels and clears under ``<entity>:labels``, ``<entity>:clear``."""
    out: dict[str, list] = {}
    for chunk in RrdReader(rrd).stream().to_chunks():
        if not chunk.entity_path.startswith(prefix):
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        times = batch.column("t").to_pylist() if "t" in names else [None] * batch.num_rows
        for column, key in (("LineStrips2D:strips", ""), ("Points2D:positions", ""), ("Points2D:labels", ":labels"),
                            ("Clear:is_recursive", ":clear")):
            if column in names:
                out.setdefault(chunk.entity_path + key, []).extend(zip(times, batch.column(column).to_pylist(),
                                                                       strict=True))
    return out


def test_paths_in_the_plane(runs, tmp_path: Path) -> None:
    """A game with positions (px<i>, py<i>): per K, each car's trail up to t, its position labelled with its agent's
    name, and its plan at t (every other stage: dashed); the road's edges once, static; a 2D view per K."""
    rrd = tmp_path / "merge.rrd"
    proc = run_cli("replay", str(runs["merge"]), "--save", str(rrd))
    assert proc.returncode == 0, proc.stderr
    got = _columns(rrd, "/algames-merge-mpc/plane")
    record = read_run(runs["merge"])
    horizon = record.config["game"]["horizon"]
    for K in (1, 3):
        states = record.messages[f"/K{K}/mpc/state"]
        assert [m["t"] for m in states] == list(range(6))  # x(0..5): 5 sampling times and the state they end in
        for c, car in enumerate(("car1", "car2", "car3")):
            base = f"/algames-merge-mpc/plane/K{K}/{car}"
            xy = [[m["x"][4 * c], m["x"][4 * c + 1]] for m in states]
            trail = got[f"{base}/trail/0"]  # (one piece: fewer than TRAIL_BLOCK sampling times)
            assert len(states) < TRAIL_BLOCK and f"{base}/trail/1" not in got
            assert [t for t, _ in trail] == list(range(6))
            for t, strips in trail:  # one strip, x(0..t)
                assert len(strips) == 1 and np.allclose(strips[0], xy[: t + 1])
            assert [(t, np.allclose(p, [xy[t]])) for t, p in got[f"{base}/position"]] == [(t, True) for t in range(6)]
            assert {tuple(v) for _, v in got[f"{base}/position:labels"]} == {(car,)}
            plans = got[f"{base}/plan"]
            assert [t for t, _ in plans] == list(range(5))
            for t, strips in plans:  # horizon + 2 predicted states: x(t) and one per stage; a dash every other stage
                assert len(strips) == (horizon + 2) // 2 and all(len(s) == 2 for s in strips)
                assert np.allclose(strips[0][0], xy[t])
            assert [t for t, _ in got[f"{base}/plan:clear"]] == [5]  # no plan at the state that ends the loop
    (edges,) = got["/algames-merge-mpc/plane/edges"]
    assert edges[0] is None and len(edges[1]) >= 2  # static: the road's top edge, the ramp's edge into the bottom one
    text = _blueprint_text(rrd)
    for K in (1, 3):
        assert f"Paths: algames-merge-mpc, K = {K}: y against x, trail up to t, plan at t (dashed)" in text
    assert text.count("ViewBlueprint:class_identifier [['2D']]") == 2 and "TimePanelBlueprint:timeline [['t']]" in text


def test_a_long_trail_is_logged_in_pieces(runs, tmp_path: Path, monkeypatch) -> None:
    """Pieces of TRAIL_BLOCK sampling times, each from the last point of the one before: together, x(0..t) at t."""
    import gnerun.view.replay as rp

    monkeypatch.setattr(rp, "TRAIL_BLOCK", 2)
    got = _columns(save([runs["merge"]], tmp_path / "pieces.rrd"), "/algames-merge-mpc/plane/K1/car2/trail")
    xy = [[m["x"][4], m["x"][5]] for m in read_run(runs["merge"]).messages["/K1/mpc/state"]]
    assert sorted(got) == [f"/algames-merge-mpc/plane/K1/car2/trail/{n}" for n in range(3)]
    for n in range(3):
        pieces = got[f"/algames-merge-mpc/plane/K1/car2/trail/{n}"]
        assert [t for t, _ in pieces] == [2 * n, 2 * n + 1]
        for t, (strip,) in pieces:
            assert np.allclose(strip, xy[max(2 * n - 1, 0): t + 1])


def test_the_logged_plan_is_the_states_the_plant_reaches_undisturbed(runs) -> None:
    """Without plant noise, the applied plan's first predicted state is x(t) and its next is x(t + 1), to the 6
    significant digits logged."""
    states = read_run(runs["merge"]).messages["/K3/mpc/state"]
    for m, after in zip(states, states[1:], strict=False):
        nx = len(m["x"])  # a row of len(x) states per stage, one after the other
        assert len(m["plan"]) == (read_run(runs["merge"]).config["game"]["horizon"] + 2) * nx
        # (logged to 6 significant digits)
        assert np.allclose(m["plan"][:nx], m["x"], rtol=1e-5, atol=0)
        assert np.allclose(m["plan"][nx:2 * nx], after["x"], rtol=1e-5, atol=1e-12)
    assert "plan" not in states[-1]


def test_many_states_get_a_view_per_vehicle_and_legends_room(runs) -> None:
    """Fig. 2a of 12 states: a view per vehicle (px<i>, py<i>, th<i>, v<i>), each time axis reaching beyond the
    last time by the room its legend takes."""
    from gnerun.view.replay import _legend_room, figure_views, record

    contents = record([runs["merge"]], _Sink())
    x_keys = [key for key in contents.views if key.startswith("fig2_x")]
    assert [contents.views[key].entities for key in x_keys] == [
        [f"algames-merge-mpc/K3/x/{s}{i}" for s in ("px", "py", "th", "v")] for i in (1, 2, 3)]
    assert contents.titles[x_keys[0]] == "Fig. 2a: x(t) (y) against sampling time t (x), K = 3: px1, py1, th1, v1"
    room = _legend_room(contents.views[x_keys[0]], 2)
    assert room == pytest.approx((7 * len("px1 (K = 3)") + 40) / 750)
    fig2 = next(f for f in figure_views(contents) if f.slug == "fig2")
    assert len(fig2.container.contents[0].contents) == 3  # the per-vehicle views, stacked beside Fig. 2b
    assert [f.slug for f in figure_views(contents)] == ["paths", "fig2"]


class _Sink:  # a recording stream that keeps nothing
    def __getattr__(self, name):
        return lambda *a, **k: None


def test_figure_views_fix_their_axes_to_the_data(runs) -> None:
    """The views' ranges hold every value drawn: a viewer opening the recording shows all of it."""
    from gnerun.view.replay import record

    contents = record([runs["loop"]], _Sink())
    loop = read_run(runs["loop"])
    e = [m["e_norm"] for K in (1, 3) for m in loop.messages[f"/K{K}/mpc/error"]]
    lo, hi = contents.views["fig2_e"].y
    assert lo < math.log10(FLOOR) and hi >= math.log10(max(e))  # the band under the floor, and every value above
    assert contents.views["fig2_e"].floor in contents.views["fig2_e"].entities  # with the floor line
    assert contents.views["fig2_e"].t == [0, loop.messages["/K1/mpc/error"][-1]["t"]]
    x = [v for m in loop.messages["/K3/mpc/state"] for v in m["x"]]  # Fig. 2a: the largest K
    assert contents.views["fig2_x"].y == [min(x), max(x)]
    assert contents.views["fig2_x"].entities == [f"paper-study2/K3/x/{s}" for s in ("x1", "x2", "x3")]


def test_compared_views_share_their_y_range_and_solves_stand_side_by_side(runs, tmp_path) -> None:
    from gnerun.view.replay import figure_views, record

    clean = tmp_path / "clean"
    solve(load_config(CONFIGS / "paper_study1.yaml"), out=clean)
    contents = record([clean, runs["solve"], runs["dist"]], _Sink())
    fig1 = [key for key in contents.views if key.startswith("fig1:")]
    fig3 = [key for key in contents.views if key.startswith("fig3:")]
    assert len(fig1) == 2 and len(fig3) == 2  # a view per solve (clean, disturbed) and per K
    for keys in (fig1, fig3):
        assert len({tuple(contents.views[k].y) for k in keys}) == 1
    fig_1 = figure_views(contents)[0]
    assert fig_1.slug == "fig1" and len(fig_1.container.contents) == 2  # side by side in one container


def test_every_K_has_a_row_of_its_own_below_the_floor(tmp_path) -> None:
    """K = 3 and 7 solve every sampling time of Study 2 (equal errors, at rounding level or 0): neither hides."""
    from gnerun.view.replay import save

    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 6, "run.K": [3, 7]}), out=tmp_path / "s2")
    errors = {K: read_run(tmp_path / "s2").messages[f"/K{K}/mpc/error"] for K in (3, 7)}
    assert [m["e_norm"] for m in errors[3]] == [m["e_norm"] for m in errors[7]]
    series = _series(save([tmp_path / "s2"], tmp_path / "s2.rrd"))
    rows = {K: _check_log10(series[f"/paper-study2/K{K}/log10_e_norm"], "t", [(m["t"], m["e_norm"])
                                                                              for m in errors[K]]) for K in (3, 7)}
    assert None not in rows.values() and rows[3] != rows[7]


def test_failed_and_fallback_steps_are_marked(tmp_path) -> None:
    from .test_figures import _synthetic_loop

    _synthetic_loop(tmp_path / "loop.mcap", "ssn", True)
    _synthetic_loop(tmp_path / "dist.mcap", "distributed", True)
    series = _series(save([tmp_path / "loop.mcap", tmp_path / "dist.mcap"], tmp_path / "marks.rrd"))
    for K in (1, 3):
        failed, fallback = series[f"/marks/K{K}/failed_steps"], series[f"/marks/K{K}/fallback_steps"]
        assert failed["t"] == [2, 5] and fallback["t"] == [4]
        drawn = dict(zip(series[f"/marks/K{K}/log10_e_norm"]["t"], series[f"/marks/K{K}/log10_e_norm"]["value"],
                         strict=True))
        assert failed["value"] == [drawn[2], drawn[5]]  # on the K's curve
        assert series[f"/marks_2/K{K}/failed_steps"]["t"] == [2, 5]  # the distributed run: along its view's top
    _synthetic_loop(tmp_path / "old.mcap", "ssn", False)  # a log without statuses: nothing is marked
    assert not any(k.endswith("_steps") for k in _series(save([tmp_path / "old.mcap"], tmp_path / "old.rrd")))


# headless screenshots -----------------------------------------------------------------------------

HAS_VULKAN = vulkan_available()


@pytest.mark.slow  # (a headless viewer: 12 s)
@pytest.mark.skipif(not HAS_VULKAN, reason="no Vulkan driver on this machine (Debian: apt-get install "
                                            "mesa-vulkan-drivers); CI installs it")
def test_screenshots_show_the_figures(runs, tmp_path: Path) -> None:
    from PIL import Image

    out = tmp_path / "shots"
    proc = run_cli("replay", str(runs["solve"]), str(runs["loop"]), str(runs["dist"]), str(runs["merge"]),
                   "--screenshot", str(out), "--size", "1200x700", timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["fig1.png", "fig2.png", "fig3.png", "paths.png"]
    # the curves are there, in their palette colours: Fig. 1 has one solve (the first colour), Fig. 2 three
    # states and two K, Fig. 3 three agents (the first three colours); the top bar is left out (its warnings
    # are orange)
    for name, colours in (("fig1.png", 1), ("fig2.png", 3), ("fig3.png", 3)):
        image = np.asarray(Image.open(out / name).convert("RGB")).astype(int)
        assert image.shape[1] >= 1200 and image.shape[0] >= 700  # logical points, times the pixel ratio
        body = image[image.shape[0] // 15:]
        for colour in PALETTE[:colours]:
            assert np.all(np.abs(body - np.array(colour)) <= 12, axis=-1).sum() > 300, (name, colour)
        # no start-up notification over the views' top right corner (a grey box about 33 bright, where the
        # views' headers are 13)
        corner = image[40:60, image.shape[1] - 300:image.shape[1] - 20].mean(axis=-1)
        assert np.median(corner) < 25, name
    # the paths in the plane, a view per K: each car's trail and position in its colour, the road's edges in grey,
    # the plans lighter
    image = np.asarray(Image.open(out / "paths.png").convert("RGB")).astype(int)
    assert image.shape[1] >= 1200 and image.shape[0] >= 700
    body = image[image.shape[0] // 15:]
    for colour in [*PALETTE[:3], EDGE_COLOUR, *(_lighter(c) for c in PALETTE[:3])]:
        assert np.all(np.abs(body - np.array(colour)) <= 12, axis=-1).sum() > 50, colour


def test_screenshots_without_vulkan_say_what_to_install(runs, tmp_path: Path, monkeypatch) -> None:
    from typer.testing import CliRunner

    import gnerun.view.replay as rp
    from gnerun.cli import app

    monkeypatch.setattr(rp, "_ICD_DIRS", ())
    monkeypatch.delenv("VK_DRIVER_FILES", raising=False)
    monkeypatch.delenv("VK_ICD_FILENAMES", raising=False)
    result = CliRunner().invoke(app, ["replay", str(runs["loop"]), "--screenshot", str(tmp_path / "s")])
    assert result.exit_code == 1
    assert "mesa-vulkan-drivers" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "s").exists()


def test_a_loop_without_z_star_shows_its_residual(tmp_path) -> None:
    """run.reference: none logs no e(t): Fig. 2b (and Fig. 3) draw log10 ||Phi|| of each sampling time's last
    iterate per K, Fig. 1 log10 ||Phi(z^k)||."""
    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 5, "run.K": [1, 3], "run.reference": "none"}),
             out=tmp_path / "run")
    rrd = save([tmp_path / "run"], tmp_path / "run.rrd")
    assert "Fig. 2b: log10 ||Phi(z^K(t))|| (no z*) (y) against sampling time t (x), per K" in _blueprint_text(rrd)
    series = _series(rrd)
    record = read_run(tmp_path / "run")
    for K in (1, 3):
        last = {}
        for m in record.messages[f"/K{K}/mpc/iterate"]:
            last[m["t"]] = m["residual_norm"]
        _check_log10(series[f"/paper-study2/K{K}/log10_residual_norm"], "t", list(last.items()))
        assert f"/paper-study2/K{K}/log10_e_norm" not in series
    # a solve: Fig. 1
    solve(load_config(CONFIGS / "paper_study1.yaml", {"run.reference": "none"}), out=tmp_path / "solve")
    rrd = save([tmp_path / "solve"], tmp_path / "solve.rrd")
    assert "Fig. 1: paper-study1 (undisturbed): log10 ||Phi(z^k)|| (no z*) (y) against iteration k (x)" in (
        _blueprint_text(rrd))
    iterates = read_run(tmp_path / "solve").messages["/solve/iterate"]
    _check_log10(_series(rrd)["/paper-study1/solve/log10_residual_norm"], "iteration",
                 [(m["k"], m["residual_norm"]) for m in iterates])
    # a distributed loop: each K's Fig. 3 view
    simulate(load_config(CONFIGS / "paper_study3.yaml", {"run.steps": 3, "run.reference": "none"}),
             out=tmp_path / "dist")
    rrd = save([tmp_path / "dist"], tmp_path / "dist.rrd")
    assert ("Fig. 3: log10 ||Phi(z^K(t))|| (no z*) (y) against sampling time t (x), paper-study3: K = 5"
            in _blueprint_text(rrd))
    series = _series(rrd)
    for K in (2, 5):
        last = {}
        for m in read_run(tmp_path / "dist").messages[f"/K{K}/mpc/iterate"]:
            last[m["t"]] = m["residual_norm"]
        _check_log10(series[f"/paper-study3/K{K}/log10_residual_norm"], "t", list(last.items()))
