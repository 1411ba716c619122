"""The figures say what their titles and legends say: the alarm figure's
colours, one legend entry per fault type, gated and oracle on top."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from matplotlib.colors import to_hex

import slam.outputs.plots
import slam.outputs.validation_figures
from slam.outputs.plots import fault_color, fault_shading, plot_trajectories
from slam.outputs.validation_figures import plot_observer_alarms
from slam.recording import COMPONENTS, SENSOR_MODALITIES, expand_sensor_labels


def capture(monkeypatch) -> list:
    """From now on, figures are collected instead of saved. (Call it after
    the session's maps are made: they must write their figures.)"""
    figures: list = []
    monkeypatch.setattr(slam.outputs.plots, "save_figure", lambda fig, path: figures.append(fig))
    monkeypatch.setattr(slam.outputs.validation_figures, "save_figure", lambda fig, path: figures.append(fig))
    return figures


@pytest.mark.slow
def test_observer_alarms_colours_rows_and_legend(mapped, monkeypatch):
    res = mapped("on")
    recording = copy.copy(res.recording)
    # Two fault types, overlapping in time: each must be told apart.
    recording.fault_truth = {**res.recording.fault_truth, "SM": [(12.0, 15.0)], "GPS": []}
    drawn = capture(monkeypatch)
    plot_observer_alarms("unused.png", recording, res.validation)
    (fig,) = drawn
    ax = fig.axes[0]
    assert "alarms (blue)" in ax.get_title() and "blamed sensors (red)" in ax.get_title()
    rows = [t.get_text() for t in ax.get_yticklabels()][::-1]  # top to bottom
    bars = [c for c in ax.collections if len(c.get_paths())]
    colours = {to_hex(c.get_facecolor()[0]) for c in bars}
    assert to_hex("tab:blue") in colours and to_hex("tab:red") in colours
    assert rows[-2:] == ["true fault: IMU_YAW", "true fault: SM"]
    # Bars above the shading, in their own colours (no blending).
    shading = [p for p in ax.patches]
    assert all(c.get_zorder() > max(p.get_zorder() for p in shading) for c in bars)
    assert all(c.get_alpha() in (None, 1.0) for c in bars)
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["true IMU_YAW fault", "true SM fault", "any true fault"]


def test_every_component_of_the_fault_truth_has_its_own_colour():
    """The truth a reader gives (truth.json's components, a whole sensor's
    label spread over its modalities) is drawn in one colour per component,
    none the grey of an unknown one or of "any true fault"."""
    truth = expand_sensor_labels({"SM": [(1.0, 2.0)], "ODO": [(3.0, 4.0)], **{c: [(5.0, 6.0)] for c in COMPONENTS}})
    colours = {label: to_hex(colour) for label, _, colour in fault_shading(truth)}
    assert len(colours) == len(COMPONENTS) and len(set(colours.values())) == len(COMPONENTS), colours
    assert not {to_hex("lightgrey"), to_hex("0.88")} & set(colours.values()), colours
    for sensor, modalities in SENSOR_MODALITIES.items():  # a whole sensor (a system model's node): its first modality's
        assert fault_color(sensor) == fault_color(modalities[0])


@pytest.mark.slow
def test_gated_and_oracle_are_drawn_on_top_and_apart(mapped, monkeypatch):
    trajectories = {name: mapped("off").trajectory for name in ("ungated", "huber", "cauchy", "dcs")}
    trajectories["oracle"] = mapped("oracle").trajectory
    trajectories["gated"] = mapped("on").trajectory
    recording = mapped("off").recording
    drawn = capture(monkeypatch)
    plot_trajectories("unused.png", trajectories, recording.groundtruth, "t", fault_shading(recording.fault_truth),
                      highlight=["oracle", "gated"])
    (fig,) = drawn
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines() if not ln.get_label().startswith("_")}
    others = [lines[n] for n in ("ungated", "huber", "cauchy", "dcs")]
    gated, oracle = lines["gated"], lines["oracle"]
    assert gated.get_zorder() > oracle.get_zorder() > max(ln.get_zorder() for ln in others)
    assert oracle.get_linewidth() > gated.get_linewidth() > max(ln.get_linewidth() for ln in others)
    colours = [to_hex(ln.get_color()) for ln in [gated, oracle, *others]]
    assert len(set(colours)) == len(colours)  # nobody shares gated's or oracle's colour
    assert lines["true IMU_YAW fault"].get_color() == "lightgreen"
    assert np.isfinite(gated.get_xdata()).all()
