"""numpy's BLAS kernels pinned by ``import slam`` (slam/host.py), so a map
is the same on every x86-64 host that can run them."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

from slam.host import NEEDS, PINNED_CORE, cpu_flags

# In a fresh interpreter: which kernels OpenBLAS took, asked through numpy's
# own copy of it (the wheel's numpy.libs), and what OPENBLAS_CORETYPE says.
PROBE = """
import ctypes, glob, json, os, sys
{first}
import numpy
libs = glob.glob(os.path.join(os.path.dirname(numpy.__file__) + ".libs", "libscipy_openblas*"))
core = None
if libs:
    f = ctypes.CDLL(libs[0]).scipy_openblas_get_corename64_
    f.restype = ctypes.c_char_p
    core = f().decode()
print(json.dumps({{"core": core, "env": os.environ.get("OPENBLAS_CORETYPE")}}))
"""


def probe(first: str, **env: str) -> dict:
    clean = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    out = subprocess.run([sys.executable, "-c", PROBE.format(first=first)], env={**clean, **env},
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def can_pin() -> bool:
    return platform.machine().lower() in ("x86_64", "amd64") and NEEDS <= cpu_flags()


def test_cpu_flags_read_the_first_processor(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nflags\t\t: fpu sse2 avx2 fma\n\nprocessor\t: 1\nflags\t\t: fpu\n")
    assert cpu_flags(str(info)) == {"fpu", "sse2", "avx2", "fma"}
    assert cpu_flags(str(tmp_path / "absent")) == frozenset()


def test_import_slam_pins_the_kernels_before_numpy_loads_them():
    if not can_pin():
        pytest.skip("not an x86-64 CPU with AVX2 and FMA: slam keeps the host's own kernels")
    got = probe("import slam")
    assert got["env"] == PINNED_CORE
    if got["core"] is None:
        pytest.skip("numpy's BLAS is not the wheel's OpenBLAS: its kernels cannot be asked for")
    assert got["core"] == PINNED_CORE


def test_a_users_choice_and_an_earlier_numpy_are_left_alone():
    assert probe("import slam", OPENBLAS_CORETYPE="Prescott")["env"] == "Prescott"
    got = probe("import numpy, slam")  # numpy first: too late to pin, and the children are not asked to
    assert got["env"] is None
