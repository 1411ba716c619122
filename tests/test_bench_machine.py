"""The machine line every benchmark page is written under (scripts.bench.common.machine)."""

from __future__ import annotations

from pathlib import Path

import pytest

from scripts.bench.common import machine


def test_the_machine_line_names_the_cpus_generation_and_vector_unit():
    """Two machines sold under one name can round differently (a wider
    vector unit, other kernels): the page says which it was."""
    cpuinfo = Path("/proc/cpuinfo")
    if not cpuinfo.exists():
        pytest.skip("no /proc/cpuinfo on this system: the line names the processor only")
    first = dict((k.strip(), v.strip()) for k, v in
                 (line.split(":", 1) for line in cpuinfo.read_text().split("\n\n")[0].splitlines() if ":" in line))
    if "cpu family" not in first or "model" not in first:
        pytest.skip("this CPU's /proc/cpuinfo gives no family and model")
    line = machine()
    assert f"(family {first['cpu family']} model {first['model']}, " in line
    flags = set(first.get("flags", "").split())
    assert ("AVX-512" in line) == ("avx512f" in flags)
