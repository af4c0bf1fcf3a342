"""Input handling and messages found rough in use (issue 15).

Numpy scalars, wording, duplicate YAML keys, randomization ranges, early argument checks,
documentation.
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import yaml

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.config import ConfigError, from_dict, load_yaml
from soft_snake_gym.params import Integrator, Rod, SimConfig


# --- numpy scalars ----------------------------------------------------------------------------
def test_numpy_scalars_are_accepted_and_stored_as_python_numbers():
    rod = Rod(N=np.int64(12), E=np.float32(2e6), edge_length=np.float16(0.25))
    assert type(rod.N) is int and rod.N == 12 and rod.length == pytest.approx(11 * 0.25)
    assert type(rod.E) is float and rod.E == pytest.approx(2e6)
    assert type(Integrator(substeps=np.int32(3)).substeps) is int
    cfg = from_dict(SimConfig, {"rod": {"N": np.uint8(5), "E": np.float32(1e6)}})
    assert type(cfg.rod.N) is int and type(cfg.rod.E) is float
    env = gym.make(
        "SoftEel-v0",
        rod={"N": np.int64(12), "E": np.float32(2e6)},
        dt=np.float32(0.02),
        max_curvature_rate=np.float32(3.0),
        randomize={"E": [np.float32(1e6), np.int64(3_000_000)]},
    )
    s = env.unwrapped.settings
    assert env.unwrapped.N == 12 and type(s.max_curvature_rate) is float
    assert s.randomize.E == (1e6, 3e6) and all(type(v) is float for v in s.randomize.E)
    hash(s)  # frozen settings stay hashable and dump to plain YAML
    assert "!!python" not in yaml.safe_dump(dataclasses.asdict(s))
    env.reset(seed=0)
    env.unwrapped.reset(options={"goal_direction": np.float32(0.5)})
    assert env.unwrapped.goal_direction == pytest.approx(0.5)
    # still refused: booleans and non-integral values for an integer field
    with pytest.raises(ValueError, match=r"Rod.N = np.True_ must be an integer|Rod.N = True"):
        Rod(N=np.bool_(True))
    with pytest.raises(ConfigError, match="must be an integer"):
        from_dict(Rod, {"N": np.float64(12.0)})


# --- wording ----------------------------------------------------------------------------------
def test_messages_name_the_range_the_path_and_end_sentences(tmp_path):
    with pytest.raises(ConfigError) as err:
        gym.make("SoftEel-v0", rod={"E": "abc"})
    assert str(err.value) == "SoftEel-v0.rod.E = 'abc' must be a number in (0.0, inf)"
    with pytest.raises(
        ConfigError, match=r"SoftEel-v0.max_curvature_rate = 'x' must be a number in \(0.0, inf\)"
    ):
        gym.make("SoftEel-v0", max_curvature_rate="x")
    with pytest.raises(ConfigError) as err:
        from_dict(Rod, {"zzzz": 1})
    assert "unknown key 'zzzz' in Rod. Valid keys: N, " in str(err.value)
    with pytest.raises(ConfigError, match="did you mean 'edge_mass'\\? Valid keys"):
        from_dict(Rod, {"edge_mas": 1})
    with pytest.raises(ConfigError, match="is a folder; give the path of a YAML file"):
        load_yaml(tmp_path)


def test_a_yaml_key_given_twice_is_an_error(tmp_path):
    path = tmp_path / "dup.yaml"
    path.write_text("rod:\n  E: 1.0e6\n  N: 12\n  E: 2.0e6\n")
    with pytest.raises(ConfigError, match=r"line 4.*duplicate key 'E' \(first given on line 2\)"):
        load_yaml(path)
    path.write_text("rod:\n  E: 1.0e6\nfluid:\n  E: 2.0e6\n")  # the same key in two mappings is fine
    assert load_yaml(path) == {"rod": {"E": 1e6}, "fluid": {"E": 2e6}}


def test_compare_title_counts_one_episode_in_the_singular():
    from soft_snake_gym.cli.compare import episodes_on_seeds

    assert episodes_on_seeds(1, 0) == "1 episode per policy, seed 0"
    assert episodes_on_seeds(3, 5) == "3 episodes per policy, seeds 5..7"


# --- documentation and the Gymnasium contract ---------------------------------------------------
@pytest.mark.parametrize("env_id", ["SoftEel-v0", "SoftWorm-v0"])
def test_help_documents_the_env_not_gymnasium_generic_text(env_id):
    import pydoc

    cls = type(gym.make(env_id).unwrapped)
    text = pydoc.render_doc(cls, renderer=pydoc.plaintext)
    assert "CartPole" not in text and "ansi" not in text
    for name in ("sim", "dt", "observation_structure"):
        assert f"``{name}``" in text, name
    for method in (cls.step, cls.reset, cls.render):
        assert method.__doc__ and "CartPole" not in method.__doc__ and "ansi" not in method.__doc__
    assert "ResetNeeded" in cls.step.__doc__


def test_ground_and_fluid_document_their_fields_with_units():
    from soft_snake_gym.params import Fluid, Ground

    for cls in (Fluid, Ground):
        doc = cls.__doc__
        for f in dataclasses.fields(cls):
            assert f"{f.name}:" in doc, (cls.__name__, f.name)
    assert "[m/s]" in Ground.__doc__ and "[m/s^2]" in Ground.__doc__ and "[kg/m^3]" in Fluid.__doc__


@pytest.mark.parametrize("env_id", ["SoftEel-v0", "SoftWorm-v0"])
def test_step_before_reset_raises_reset_needed_without_gym_make(env_id):
    from soft_snake_gym.envs import InchEnv, SwimEnv

    env = {"SoftEel-v0": SwimEnv, "SoftWorm-v0": InchEnv}[env_id]()
    with pytest.raises(gym.error.ResetNeeded, match="call reset"):
        env.step(env.action_space.sample())
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))


# --- the README's snippets and the version --------------------------------------------------------
ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def _readme_block(after: str, lang: str = "python") -> str:
    """The first fenced ``lang`` block of README.md after the line containing ``after``."""
    text = (ROOT / "README.md").read_text()
    start = text.index(f"```{lang}\n", text.index(after)) + len(lang) + 4
    return text[start : text.index("```", start)]


def test_readme_simulator_snippet_prints_what_the_readme_shows(capsys, monkeypatch):
    code = _readme_block("## The simulator")
    shown = _readme_block("## The simulator", "text")
    monkeypatch.chdir(ROOT)
    exec(compile(code, "README.md", "exec"), {})
    assert capsys.readouterr().out == shown


def test_readme_pid_snippet_runs_without_warnings(monkeypatch):
    import warnings

    code = _readme_block("through SB3's `evaluate_policy`, exactly as a trained agent does.")
    assert "evaluate_policy(pid, env" in code
    monkeypatch.chdir(ROOT)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        exec(compile(code, "README.md", "exec"), {})


def test_readme_and_rod_say_that_n_adds_edges_of_the_same_length():
    rod = Rod(N=300)
    assert round(rod.length, 1) == 53.8 and round(rod.total_mass) == 239
    assert "`N = 300` is a 53.8 m body of 239 kg" in (ROOT / "README.md").read_text()
    assert "N = 300 is a 53.8 m body" in " ".join(Rod.__doc__.split())


def test_version_option(capsys):
    from soft_snake_gym.cli import main

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"soft-snake {soft_snake_gym.__version__}"


# --- randomization ranges -------------------------------------------------------------------------
def test_randomization_ranges_that_break_mu_d_le_mu_s_are_rejected():
    with pytest.raises(ConfigError, match=r"randomize.mu_d high 2.0 exceeds ground.mu_s = 1.15"):
        gym.make("SoftWorm-v0", randomize={"mu_d": [1.0, 2.0]})
    with pytest.raises(ConfigError, match=r"randomize.mu_d high 0.9 exceeds randomize.mu_s low 0.8"):
        gym.make("SoftWorm-v0", randomize={"mu_s": [0.8, 1.2], "mu_d": [0.5, 0.9]})
    with pytest.raises(ConfigError, match=r"ground.mu_d = 0.8 exceeds randomize.mu_s low 0.5"):
        gym.make("SoftWorm-v0", randomize={"mu_s": [0.5, 1.2]})
    env = gym.make("SoftWorm-v0", randomize={"mu_s": [0.8, 1.2], "mu_d": [0.5, 0.8]})
    for seed in range(20):  # every draw is used as drawn, none clipped
        drawn = env.reset(seed=seed)[1]["randomized"]
        cfg = env.unwrapped.sim.config
        assert drawn["mu_d"] <= drawn["mu_s"]
        assert (cfg.ground.mu_s, cfg.ground.mu_d) == (drawn["mu_s"], drawn["mu_d"])


@pytest.mark.parametrize(
    "env_id,key,unused", [("SoftEel-v0", "mu_s", "ground"), ("SoftWorm-v0", "C_D", "fluid")]
)
def test_randomizing_what_the_medium_ignores_is_rejected(env_id, key, unused):
    with pytest.raises(
        ConfigError, match=rf"{env_id}.randomize: {key} has no effect .*\({unused} parameters\)"
    ):
        gym.make(env_id, randomize={"E": [1e6, 2e6], key: [0.5, 0.6]})


def test_randomized_length_lag_is_checked_before_any_episode():
    with pytest.raises(ConfigError, match=r"SoftEel-v0.randomize: length_lag has no effect in the water"):
        gym.make("SoftEel-v0", randomize={"length_lag": [0.01, 0.1]})
    with pytest.raises(ConfigError, match=r"length_lag = \[0.0, 20.0\] reaches past .* \[0, 10\] s"):
        gym.make("SoftWorm-v0", randomize={"length_lag": [0.0, 20.0]})


def test_symplectic_with_tens_of_thousands_of_substeps_warns():
    with pytest.warns(UserWarning, match=r"symplectic_euler' takes [\d,]+ sub-steps per h = 0.01 s"):
        gym.make(
            "SoftEel-v0", integrator={"method": "symplectic_euler"}, rod={"E": 2e10, "damping_bend": 0.1}
        )
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym.make("SoftEel-v0", integrator={"method": "symplectic_euler"}, rod={"damping_bend": 0.1})


# --- the command line checks everything before any work ----------------------------------------
def _one_line_error(main_args, capsys, code=2) -> str:
    from soft_snake_gym.cli import main

    assert main(main_args) == code
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.fixture
def no_work(monkeypatch):
    """Make any episode or env construction fail loudly: the checks must come first."""
    import soft_snake_gym.cli.compare as compare_cli
    import soft_snake_gym.cli.evaluate as evaluate_cli
    import soft_snake_gym.evaluation as evaluation

    def boom(*args, **kwargs):
        raise AssertionError("work started before the arguments were checked")

    monkeypatch.setattr(evaluation, "evaluate", boom)
    monkeypatch.setattr(evaluate_cli, "evaluate", boom)  # the commands call the names they import
    monkeypatch.setattr(compare_cli, "compare", boom)
    import soft_snake_gym.studies.sweep as sweep_mod

    monkeypatch.setattr(sweep_mod, "run_cell", boom)


def test_evaluate_without_the_video_extra_fails_before_the_episode(monkeypatch, capsys, no_work, tmp_path):
    import sys

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # as if the extra were not installed
    err = _one_line_error(
        ["evaluate", "SoftEel-v0", "--policy", "pid", "--video", str(tmp_path / "x.mp4")], capsys
    )
    assert "needs imageio with ffmpeg (pip install 'soft-snake-gym[video]'); or give a .gif path" in err


@pytest.mark.parametrize(
    "transient,message",
    [
        ("20", "transient = 20 s is longer than half the 10 s episode"),
        ("-1", "--transient -1 must be a number of seconds >= 0"),
        ("nan", "--transient nan must be"),
    ],
)
def test_evaluate_rejects_a_transient_that_leaves_no_window(transient, message, capsys, no_work):
    err = _one_line_error(["evaluate", "SoftEel-v0", "--policy", "pid", "--transient", transient], capsys)
    assert message in err


def test_evaluate_header_says_when_episodes_were_too_short_for_the_transient(capsys):
    from soft_snake_gym.cli import main

    # a gait that folds the soft eel onto itself within 0.3 s
    assert (
        main(
            [
                "evaluate",
                "SoftEel-v0",
                "--policy",
                "open-loop:alpha=2.5,omega=6",
                "--episodes",
                "2",
                "--env-kwarg",
                "max_curvature_rate=200",
                "--env-kwarg",
                "max_rest_curvature=10",
                "--max-steps",
                "300",
                "--transient",
                "1",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "metrics after a 1 s transient (over the whole episode for 2 of 2 that ended before 2 s)" in out
    assert "2 episode(s) ended in a failure: self_intersection" in out


def test_evaluate_warns_when_a_baseline_gait_saturates_the_actions(capsys):
    from soft_snake_gym.cli import main

    assert (
        main(
            [
                "evaluate",
                "SoftEel-v0",
                "--policy",
                "pid:alpha=3,omega=100",
                "--episodes",
                "1",
                "--max-steps",
                "10",
                "--transient",
                "0",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("soft-snake evaluate: warning: the alpha = 3 rad, omega = 100")
    assert "beyond the env's max_curvature_rate = 6.28 1/s" in err[0]
    assert (
        main(
            [
                "evaluate",
                "SoftWorm-v0",
                "--policy",
                "inching:omega=20",
                "--episodes",
                "1",
                "--max-steps",
                "10",
                "--transient",
                "0",
            ]
        )
        == 0
    )
    assert "beyond the env's max_length_rate = 0.3 m/s" in capsys.readouterr().err
    assert (
        main(
            [
                "evaluate",
                "SoftEel-v0",
                "--policy",
                "pid",
                "--episodes",
                "1",
                "--max-steps",
                "10",
                "--transient",
                "0",
            ]
        )
        == 0
    )
    assert capsys.readouterr().err == ""  # the default gait fits


def test_compare_checks_the_chart_format_first(capsys, no_work, tmp_path):
    err = _one_line_error(
        ["compare", "SoftEel-v0", "--policies", "pid", "--out", str(tmp_path / "x.txt")], capsys
    )
    assert "cannot draw a chart into" in err and ".png" in err


@pytest.mark.parametrize(
    "args,message",
    [
        (["--alpha-max", "4"], "--alpha-max 4 must be below pi rad"),
        (["--workers", "0"], "--workers 0 must be at least 1"),
        (["--workers", "-3"], "--workers -3 must be at least 1"),
        (["--out", "{file}"], "is a file; give a folder"),
    ],
)
def test_sweep_checks_its_arguments_first(args, message, capsys, no_work, tmp_path):
    file = tmp_path / "taken.csv"
    file.write_text("")
    args = [a.replace("{file}", str(file)) for a in args]
    err = _one_line_error(["sweep", "swim-gait", "--no-progress", *args], capsys)
    assert message in err


def test_sweep_exits_nonzero_when_cells_could_not_run(capsys, no_work, tmp_path):
    from soft_snake_gym.cli import main

    code = main(
        [
            "sweep",
            "swim-gait",
            "--no-progress",
            "--workers",
            "1",
            "--n-alpha",
            "1",
            "--n-omega",
            "1",
            "--out",
            str(tmp_path),
        ]
    )
    assert code == 1
    err = capsys.readouterr().err
    assert "2 cells could not run" in err and "work started before" in err


# --- sweep heatmaps -------------------------------------------------------------------------------
def test_heatmap_axes_span_the_grid_cells_not_beyond(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from soft_snake_gym import plots
    from soft_snake_gym.plots import cell_edges, sweep_heatmaps
    from soft_snake_gym.studies.sweep import STUDIES

    np.testing.assert_allclose(cell_edges([0.15, 1.52]), [0.15, 0.835, 1.52])
    np.testing.assert_allclose(cell_edges([0.2, 0.4, 1.0]), [0.2, 0.3, 0.7, 1.0])  # uneven spacing
    rows = [
        {
            "controller": c,
            "alpha": a,
            "omega": w,
            "E_bend": 1.87e4,
            "average_speed": a * w,
            "curvature_error": 0.1,
            "mean_fluid_power": 1.0,
            "failure": "",
        }
        for c in ("open-loop", "pid")
        for a in (0.15, 1.52)
        for w in (0.5, 3.1416)
    ]
    drawn = []
    save = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path, dpi: drawn.append(fig) or save(fig, path, dpi))
    assert sweep_heatmaps(STUDIES["swim-gait"], rows, tmp_path)
    fig = drawn[0]  # average speed: the first metric
    assert isinstance(fig, Figure) and fig.canvas.get_default_filetype() == "png"
    ax = fig.axes[0]
    assert ax.get_ylim() == pytest.approx((0.15, 1.52)) and ax.get_xlim() == pytest.approx((0.5, 3.1416))
    assert [t.get_text() for t in ax.get_yticklabels()] == ["0.15", "1.52"]
