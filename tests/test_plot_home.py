"""Where matplotlib keeps its folders while gslam runs (slam.outputs.plot_home)."""

from __future__ import annotations

import logging
import os
from pathlib import Path

from slam.outputs.plot_home import plot_home


def test_an_unusable_mplconfigdir_gets_a_temporary_folder_that_goes_and_no_font_cache_notice(tmp_path: Path,
                                                                                           monkeypatch, caplog):
    (tmp_path / "a-file").write_text("mine\n")
    monkeypatch.setenv("MPLCONFIGDIR", str(tmp_path / "a-file"))
    fonts = logging.getLogger("matplotlib.font_manager")
    with caplog.at_level(logging.WARNING, logger="matplotlib.font_manager"):
        with plot_home():
            folder = Path(os.environ["MPLCONFIGDIR"])
            assert folder.is_dir() and folder != tmp_path / "a-file"
            fonts.warning("Matplotlib is building the font cache; this may take a moment.")
            fonts.warning("findfont: Font family 'Nowhere' not found.")
        fonts.warning("Matplotlib is building the font cache; this may take a moment.")
    said = [r.getMessage() for r in caplog.records]
    # Inside, the notice of gslam's own temporary cache is not shown; any other line is,
    # and outside (matplotlib's own folders) the notice is matplotlib's as ever.
    assert said == ["findfont: Font family 'Nowhere' not found.",
                    "Matplotlib is building the font cache; this may take a moment."]
    assert not folder.exists() and os.environ["MPLCONFIGDIR"] == str(tmp_path / "a-file")
