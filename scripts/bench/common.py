"""What the benches share: the repository's paths, the robust-kernel
variants they compare against, and config building."""

from __future__ import annotations

import copy
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
KERNELS = ("huber", "cauchy", "dcs", "gnc_tls", "gnc_gm")
"""The robust-kernel variants of ``configs/variants.yaml`` (all ungated)."""


def base_config(config_path: Path, added: list[dict], folder: Path, off: tuple[str, ...] = ()) -> Path:
    """The dataset config with ``added`` relations (and their model lines)
    beside its own and the checks ``off`` turned off."""
    tree = yaml.safe_load(config_path.read_text())
    tree = copy.deepcopy(tree)
    for check in off:
        tree["validation"]["observers"].setdefault(check, {})["enabled"] = False
    model_path = (config_path.parent / tree["validation"]["model"]).resolve()
    model = yaml.safe_load(model_path.read_text())
    for rel in added:
        tree["validation"]["observers"]["relations"].append(rel)
        model["relations"][rel["name"]] = ["IMU_YAW", "IMU_GYRO"]
    tree["validation"]["model"] = model
    out = folder / f"base_{len(list(folder.glob('base_*')))}.yaml"
    out.write_text(yaml.safe_dump(tree, sort_keys=False))
    return out
