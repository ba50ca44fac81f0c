"""The user-facing layer: command line (``motionx``), the HTTP service and the job runners.

Importing it caps the BLAS/OpenMP thread pools at one thread (unless the environment already
sets them), before numpy or CasADi load: the spacetime NLP's matrices are small, IPOPT/MUMPS
and numpy gain nothing from BLAS threads, and their spinning threads slow the derivative
evaluations that CasADi runs on its own threads, and every parallel job on the same cores
(measured: a HalfBoy tutor correction 3.1 s → 2.6 s, its Hessian evaluations 1.75 s → 1.15 s).
"""

import os as _os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_name, "1")
