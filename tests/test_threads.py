"""One BLAS thread for gnerun's linear algebra unless the user chose otherwise (a subprocess per case: the BLAS
thread count is process-wide)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

PROBE = """
import json, numpy, gnerun
from threadpoolctl import threadpool_info
cfg = gnerun.load_config("{config}")
gnerun.make_solver(cfg, gnerun.compile_game(cfg))
print(json.dumps([i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]))
"""


def _blas_threads(env: dict[str, str]) -> list[int]:
    from .conftest import CONFIGS

    code = PROBE.format(config=CONFIGS / "paper_study1.yaml")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _clean_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                             "MKL_NUM_THREADS")}


def test_a_solver_built_after_numpy_was_loaded_uses_one_blas_thread() -> None:
    threads = _blas_threads(_clean_env())
    assert threads and all(t == 1 for t in threads)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs two cores to tell a user's choice from the default")
def test_a_thread_count_the_user_set_is_kept() -> None:
    threads = _blas_threads({**_clean_env(), "OPENBLAS_NUM_THREADS": "2"})
    assert threads and all(t == 2 for t in threads)
