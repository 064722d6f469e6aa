"""The ``dampest`` command line (one module per sub-command)."""

from dampest_ros.threads import one_blas_thread

# before numpy is first imported: the vehicle and the arm commands alike
one_blas_thread()
