"""Figures: drawn on their own Agg canvas, never through pyplot or a global backend; the
reproduction report's template has no number typed in."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import soft_snake_gym.studies.reproduce as reproduce


def test_a_figure_leaves_pyplot_and_the_backend_alone(tmp_path):
    code = f"""
import sys
import matplotlib
backend = dict.__getitem__(matplotlib.rcParams, "backend")  # get_backend() would import pyplot
from soft_snake_gym import plots
path = plots.comparison_chart({{"pid": {{"average_speed": (0.1, 0.01)}}, "open-loop": {{"average_speed": (0.2, 0.02)}}}},
                              [("average_speed", "average speed", "m/s")], {str(tmp_path / "chart.png")!r})
assert path.read_bytes()[:8] == b"\\x89PNG\\r\\n\\x1a\\n", "not a PNG"
assert "matplotlib.pyplot" not in sys.modules, "pyplot was imported"
assert dict.__getitem__(matplotlib.rcParams, "backend") == backend, "the global backend changed"
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr


def test_the_report_template_has_no_number_typed_in():
    text = reproduce.TEMPLATE.read_text()
    bare = re.sub(r"\$\{\w+\}", "", text)
    # digits that are names, not numbers: env ids, section signs, SB3, t = 0 (the start)
    bare = re.sub(r"-v0|§\d+|SB3|t = 0\b", "", bare)
    assert not re.findall(r".{20}\d.{20}", bare), "a number is typed into the template"


def test_the_report_fills_every_placeholder(tmp_path):
    extras = {"comparison_errors": {"centralized": 0.01, "decentralized": 0.02}, "sweeps": {}, "grid": "-"}
    text = reproduce.write_report(tmp_path / "r.md", tmp_path / "img", [], extras).read_text()
    assert "$" not in text
    assert "with gains (10, 1, 5) and the open loop at omega = 2 pi/3 rad/s" in text  # HEADLINE_GAINS, _OMEGA
    assert "0.0100 with the centralized clock and 0.0200" in text
    assert Path(reproduce.__file__).with_name("thesis_reproduction.md") == reproduce.TEMPLATE
