"""The README's first figure is what ``gslam demo`` draws: the variants the
figure shows (its PNG's Description, written by plot_trajectories) are the
demo's, and its caption names those and no other variant."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from slam.commands.compare import load_variants
from slam.commands.demo import DEFAULT_SCENARIO, DEFAULT_VARIANTS, run_demo
from slam.outputs.plots import TRAJECTORIES_DESCRIPTION, png_description
from slam.resources import shipped_config
from slam.sim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
COUNTS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7, "eight": 8, "nine": 9,
          "ten": 10}


def first_figure() -> tuple[str, Path, str]:
    """The README's first image: its alt text, its file and the italic
    caption paragraph under it."""
    text = (ROOT / "README.md").read_text()
    image = re.search(r"!\[([^\]]*)\]\(([^)]+)\)\n\n\*([^*]+)\*", text)
    assert image is not None, "the README's first figure has no caption paragraph (*...*) under it"
    return image.group(1), ROOT / image.group(2), " ".join(image.group(3).split())


def drawn_variants(png: Path) -> list[str]:
    description = png_description(png) or ""
    assert description.startswith(TRAJECTORIES_DESCRIPTION), f"{png} was not drawn by plot_trajectories"
    return description.removeprefix(TRAJECTORIES_DESCRIPTION).split(", ")


def named_variants(text: str) -> set[str]:
    """The shipped variants a text names, as whole words."""
    known = load_variants(shipped_config("variants.yaml"))
    return {v for v in known if re.search(rf"(?<![\w-]){re.escape(v)}(?![\w-])", text)}


def test_readme_figure_shows_the_demos_variants():
    alt, png, caption = first_figure()
    assert drawn_variants(png) == list(DEFAULT_VARIANTS)
    for text in (alt, caption):
        assert named_variants(text) == set(DEFAULT_VARIANTS), text
        counts = [COUNTS[w] for w in re.findall(r"\b(\w+) variants\b", text) if w in COUNTS]
        assert counts and set(counts) == {len(DEFAULT_VARIANTS)}, text


def test_readme_caption_names_the_demos_scenario_seed():
    _, _, caption = first_figure()
    seed = load_scenario(shipped_config(DEFAULT_SCENARIO)).seed
    assert re.findall(r"\bseed (\d+)", caption) == [str(seed)]


@pytest.mark.slow
def test_demo_draws_its_variants(short_scenario_yaml, tmp_path):
    res = run_demo(tmp_path / "demo", scenario=short_scenario_yaml)
    assert drawn_variants(res.compare.out_dir / "trajectories.png") == list(DEFAULT_VARIANTS)
