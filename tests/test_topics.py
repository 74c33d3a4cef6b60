"""Topic names: built and parsed in one place (gnerun.log.topics), and a simulate log uses no other."""

from __future__ import annotations

from gnerun.language.config import load_config
from gnerun.log import topics
from gnerun.log.mcap_log import read_run
from gnerun.runs.closed_loop import simulate

from .conftest import CONFIGS


def test_a_closed_loop_topic_parses_back_to_its_budget_and_kind() -> None:
    for K in (1, 7, 100_000):
        for kind in topics.MPC_KINDS:
            assert topics.parse_mpc(topics.mpc(K, kind)) == (K, kind)
    assert topics.mpc(7, "state") == "/K7/mpc/state"


def test_other_topics_are_not_closed_loop_topics() -> None:
    for topic in (topics.LOG, topics.SOLVE_ITERATE, "/K/mpc/state", "/K7/mpc/other", "/K7/mpc/state/x", "K7/mpc/state",
                  "/k7/mpc/state", "/K-1/mpc/state"):
        assert topics.parse_mpc(topic) is None, topic


def test_a_simulate_log_holds_only_these_topics(tmp_path) -> None:
    cfg = load_config(CONFIGS / "paper_study2.yaml", {"run.K": [1, 3], "run.steps": 2})
    simulate(cfg, tmp_path / "run")
    written = set(read_run(tmp_path / "run").messages)
    assert written == {topics.LOG} | {topics.mpc(K, kind) for K in (1, 3) for kind in topics.MPC_KINDS}
