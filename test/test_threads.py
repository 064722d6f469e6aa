"""One BLAS thread in the processes dampest_ros starts, unless the user set a number."""

from __future__ import annotations

import os
import subprocess
import sys

from dampest_ros.threads import VARIABLES

_PROBE = ("import os, dampest_ros.cli, numpy as np, scipy.linalg; "
          "a = np.random.default_rng(0).random((60, 60)); a @ a; scipy.linalg.qr(a); "
          "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'], "
          "len(os.listdir('/proc/self/task')))")


def _probe(**env: str) -> list[str]:
    clean = {k: v for k, v in os.environ.items() if k not in VARIABLES}
    out = subprocess.run([sys.executable, "-c", _PROBE], env={**clean, **env},
                         capture_output=True, text=True, check=True).stdout
    return out.split()


def test_the_command_runs_numpy_on_one_thread() -> None:
    assert _probe() == ["1", "1", "1"]  # one thread in the whole process


def test_a_number_the_user_set_is_kept() -> None:
    blas, omp, threads = _probe(OPENBLAS_NUM_THREADS="2")
    assert (blas, omp) == ("2", "1") and int(threads) > 1  # OpenBLAS started its own thread
