"""Tools beside the package: the benchmark harness (:mod:`scripts.bench`) and
the data sets' sources and checksums (``scripts/datasets.py``)."""
