"""The same numbers on every x86-64 host: numpy's BLAS kernels pinned.

numpy's OpenBLAS chooses its kernels for the CPU it runs on, and the
kernels of different CPUs sum a matrix product in different orders. A map
that hangs on one weak match then differs from host to host. On intel
with the CARMEN config, on one AMD EPYC (family 25, AVX2), the ATE was
0.0811 m with OpenBLAS's Haswell or Zen kernels, 0.0911 m with its Sandy
Bridge ones and 0.0798 m with Prescott's (``OPENBLAS_CORETYPE``).

:func:`pin_blas_kernels` therefore asks for the Haswell kernels wherever
the CPU can run them (AVX2 and FMA: every x86-64 server CPU since about
2015). The products, and with them the maps, are then the same on each
such host. OpenBLAS reads the setting once, when numpy loads it, so
``import slam`` pins it before anything imports numpy. Three cases keep
the host's own kernels:

- an ``OPENBLAS_CORETYPE`` the user set stays theirs;
- a process that imported numpy before slam keeps them, and its children
  do too, so that both sides of the run use the same kernels;
- other CPUs and systems (ARM, or no ``/proc/cpuinfo`` to read) keep them.
"""

from __future__ import annotations

import os
import platform
import sys

PINNED_CORE = "Haswell"
"""OpenBLAS's name for its AVX2 and FMA kernels."""
NEEDS = frozenset({"avx2", "fma"})
"""The CPU flags those kernels need (Linux's names in ``/proc/cpuinfo``)."""


def cpu_info(path: str = "/proc/cpuinfo") -> dict[str, str]:
    """The first processor's fields of ``path`` (empty where it cannot be read)."""
    try:
        with open(path, encoding="ascii", errors="replace") as f:
            first = f.read().split("\n\n")[0]
    except OSError:
        return {}
    pairs = (line.split(":", 1) for line in first.splitlines() if ":" in line)
    return {k.strip(): v.strip() for k, v in pairs}


def cpu_flags(path: str = "/proc/cpuinfo") -> frozenset[str]:
    """The first processor's flags; empty where ``path`` cannot be read."""
    return frozenset(cpu_info(path).get("flags", "").split())


def pin_blas_kernels() -> str | None:
    """Pin OpenBLAS's kernels (module docstring). Returns the kernels
    OpenBLAS is asked for, or None where the host's own are used."""
    if "OPENBLAS_CORETYPE" in os.environ:
        return os.environ["OPENBLAS_CORETYPE"]
    if "numpy" in sys.modules or platform.machine().lower() not in ("x86_64", "amd64"):
        return None
    if not NEEDS <= cpu_flags():
        return None
    os.environ["OPENBLAS_CORETYPE"] = PINNED_CORE
    return PINNED_CORE
