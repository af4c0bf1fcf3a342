"""Figures.

Drawn on their own Agg canvas, never through pyplot or a global backend; the reproduction report's
template has no number typed in.
"""

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


def _capture(monkeypatch) -> list:
    """Keep each figure drawn (and still write it)."""
    from soft_snake_gym import plots

    drawn = []
    save = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path, dpi: drawn.append(fig) or save(fig, path, dpi))
    return drawn


def test_comparison_chart_draws_each_policys_mean_with_its_std(tmp_path, monkeypatch):
    from soft_snake_gym import plots

    drawn = _capture(monkeypatch)
    results = {"pid": {"average_speed": (0.1, 0.01)}, "open-loop": {"average_speed": (0.2, 0.03)}}
    path = plots.comparison_chart(
        results, [("average_speed", "average speed", "m/s")], tmp_path / "c" / "x.png"
    )
    assert path.is_file()
    ax = drawn[0].axes[0]
    assert [p.get_height() for p in ax.patches] == [0.1, 0.2]
    assert ax.get_ylabel() == "average speed [m/s]"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["pid", "open-loop"]


def test_comparison_chart_draws_a_seed_sets_interval_not_a_spread(tmp_path, monkeypatch):
    import numpy as np

    from soft_snake_gym import plots

    drawn = _capture(monkeypatch)
    results = {"pid": {"average_speed": (0.1, 0.01)}, "runs/x": {"average_speed": (0.05, 0.02, 0.09)}}
    plots.comparison_chart(results, [("average_speed", "average speed", "m/s")], tmp_path / "x.png")
    ax = drawn[0].axes[0]
    assert [p.get_height() for p in ax.patches] == [0.1, 0.05]
    assert [p.get_hatch() for p in ax.patches] == [None, "//"]
    (segments,) = [c.get_segments() for c in ax.collections]  # the error bars: (x, lo) to (x, hi)
    spans = [sorted(np.asarray(seg)[:, 1]) for seg in segments]
    assert np.allclose(spans, [[0.09, 0.11], [0.02, 0.09]])


def test_learning_curve_is_drawn_from_the_run_folder(tmp_path, monkeypatch):
    import csv

    import yaml

    from soft_snake_gym.training import load_train_config, plot_learning_curve

    cfg = load_train_config("SoftEel-v0", overrides={"eval_episodes": 2, "eval_freq": 100})
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg.to_yaml_dict(), sort_keys=False))
    rows = [
        {
            "timesteps": s,
            "return_mean": 1.0,
            "average_speed_mean": v,
            "average_speed_std": 0.01,
            "cost_of_transport_mean": 2.0,
            "cost_of_transport_std": 0.1,
            "baseline_average_speed": 0.05,
            "baseline_cost_of_transport": 3.0,
        }
        for s, v in ((100, 0.02), (200, 0.04))
    ]
    with open(tmp_path / "learning_curve.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    drawn = _capture(monkeypatch)
    assert plot_learning_curve(tmp_path) == tmp_path / "learning_curve.png"
    speed = drawn[0].axes[0]
    agent, baseline = speed.lines[0], speed.lines[1]
    assert list(agent.get_xdata()) == [100, 200] and list(agent.get_ydata()) == [0.02, 0.04]
    assert list(baseline.get_ydata()) == [0.05, 0.05]
    assert "2 fixed seeds every 100 steps" in drawn[0].get_suptitle()
