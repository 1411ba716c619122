"""The machine line every benchmark page is written under (scripts.bench.common.machine)."""

from __future__ import annotations

import pytest

from scripts.bench.common import cpu_info, machine


def test_the_machine_line_names_the_cpus_generation_and_vector_unit():
    """Two machines sold under one name can round differently (a wider
    vector unit, other kernels): the page says which it was."""
    first = cpu_info()
    if "cpu family" not in first or "model" not in first:
        pytest.skip("no CPU family and model in /proc/cpuinfo here: the line names the processor only")
    line = machine()
    assert f"(family {first['cpu family']} model {first['model']}, " in line
    flags = set(first.get("flags", "").split())
    assert ("AVX-512" in line) == ("avx512f" in flags)
