"""directgeo onboard: receiver link, raw journal, camera time marks and the RTK engine."""

import os

# One BLAS thread, set before numpy is first imported (OpenBLAS reads it when it loads): numpy's OpenBLAS
# otherwise starts a thread per core at import, which costs CPU at every start (`import numpy` 0.11 -> 0.06 s
# CPU, `onboard rtk` start-up 0.17 -> 0.11 s, measured on the 2-core dev machine) and buys nothing for the
# engine's matrices (at most ~40x40, where BLAS threads only add synchronisation); on the Pi the recorder and
# the web server share 4 cores. setdefault: a user's own setting wins. A process that imported numpy before
# `onboard` (e.g. the ground app, `python -m ground`) keeps its threads; the variable then only reaches its
# child processes.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
