"""The ``dampest`` command line (one module per sub-command)."""

import os

# One BLAS thread, set before numpy is first imported (as in dampest_ros.ros): the small
# matrices of the recursive and chunked solvers run slower with BLAS threads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
