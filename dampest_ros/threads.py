"""One thread per BLAS pool in the processes dampest_ros starts (the ``dampest`` command and
the nodes), set in this one place.

dampest's matrices are small (an arm's 84 regressor columns, the vehicle's RLS blocks): BLAS
threads do not speed them up, and on a loaded machine they oversubscribe it. On two cores
shared with other work, ``dampest arm identify`` of 60 s of UR5 data took 55–69 s with two
OpenBLAS threads and 6–7.5 s with one (docs/architecture.md §6). The limits are environment
defaults that OpenBLAS (its pthreads and OpenMP builds) and MKL read when they load, so they
act only if set before numpy is first imported; a value the user exported is kept.
"""

from __future__ import annotations

import os

#: The variables that size the thread pools numpy's and scipy's BLAS may use.
VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread() -> None:
    """Default each of :data:`VARIABLES` to 1 (those already set are kept)."""
    for name in VARIABLES:
        os.environ.setdefault(name, "1")
