"""The benchmark harness: every benchmark and tuning run of the project, run
from the repository root as

    python -m scripts.bench NAME [ARGS ...]
    python -m scripts.bench NAME --help
    python -m scripts.bench --help          # the list

Each benchmark is a module here with a ``main(argv)``; what they share
(paths, the robust-kernel list, config building) is in :mod:`.common`, and
the judges of a real recording's own faults in :mod:`.judges`.
"""

import slam  # noqa: E402,F401  (first: numpy's BLAS kernels pinned as gslam pins them, slam/host.py)
