"""Where each recorded data set comes from, and a checksum check of the
local copies.

    python scripts/datasets.py list
    python scripts/datasets.py verify [--root DIR]

The data root defaults to ``$GSLAM_DATA`` or ``../shared/data`` beside the
project (see :mod:`slam.readers.datasets`). ``verify`` exits with 1 when a file is
missing or differs.
"""

from __future__ import annotations

import argparse
from pathlib import Path


from slam.readers.datasets import CHECKSUMS, DATASETS, FileStatus, data_root, verify


def _list() -> int:
    for ds in DATASETS:
        n = sum(1 for rel in CHECKSUMS if rel.startswith(ds.folder + "/"))
        print(f"{ds.folder}/  ({n} files, reader '{ds.reader}')")
        print(f"    {ds.description}")
        print(f"    source:  {ds.source}")
        print(f"    licence: {ds.licence}")
    print(f"data root: {data_root()}")
    return 0


def _verify(root: Path | None) -> int:
    root = data_root() if root is None else root
    status = verify(root)
    for rel, st in status.items():
        print(f"{st.value:9s} {rel}")
    bad = [rel for rel, st in status.items() if st is not FileStatus.OK]
    ok = len(status) - len(bad)
    print(f"{root}: {ok} of {len(status)} files verified" + (f", {len(bad)} missing or different" if bad else ""))
    return 1 if bad else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="print where each data set comes from")
    v = sub.add_parser("verify", help="check the SHA-256 of the local copies")
    v.add_argument("--root", type=Path, default=None, help="data root (default: $GSLAM_DATA or ../shared/data)")
    args = parser.parse_args(argv)
    if args.command == "list":
        return _list()
    return _verify(args.root)


if __name__ == "__main__":
    from slam.errors import run_script

    run_script("datasets", main)
