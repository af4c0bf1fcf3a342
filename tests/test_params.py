"""Parameters reject impossible values; YAML maps one to one onto them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from soft_snake_gym import Fluid, Ground, Integrator, Rod, SimConfig
from soft_snake_gym.config import ConfigError, from_dict, load_sim_config, load_yaml

CONFIGS = Path(__file__).resolve().parents[1] / "soft_snake_gym" / "configs" / "env"


@pytest.mark.parametrize(
    "make,field,value",
    [
        (lambda: Rod(N=2), "Rod.N", "2"),
        (lambda: Rod(N=10.5), "Rod.N", "10.5"),
        (lambda: Rod(edge_mass=-0.8), "Rod.edge_mass", "-0.8"),
        (lambda: Rod(edge_length=0.0), "Rod.edge_length", "0.0"),
        (lambda: Rod(a=float("nan")), "Rod.a", "nan"),
        (lambda: Rod(E_bend=-1.0), "Rod.E_bend", "-1.0"),
        (lambda: Rod(damping_bend=-0.1), "Rod.damping_bend", "-0.1"),
        (lambda: Rod(damping_stretch=float("nan")), "Rod.damping_stretch", "nan"),
        (lambda: Rod(damping=1.0), "damping_bend", "damping_stretch"),
        (lambda: Rod(length_lag=-0.01), "Rod.length_lag", "-0.01"),
        (lambda: Rod(length_lag=float("inf")), "Rod.length_lag", "inf"),
        (lambda: Fluid(rho=-1.0), "Fluid.rho", "-1.0"),
        (lambda: Fluid(added_mass="munk"), "Fluid.added_mass", "munk"),
        (lambda: Ground(mu_s=0.5, mu_d=0.8), "Ground.mu_d", "0.8"),
        (lambda: Ground(V_tol=0.0), "Ground.V_tol", "0.0"),
        (lambda: Ground(mu_forward=2.0), "Ground.mu_forward", "2.0"),
        (lambda: Ground(mu_lateral=-0.1), "Ground.mu_lateral", "-0.1"),
        (lambda: Integrator(h=0.0), "Integrator.h", "0.0"),
        (lambda: Integrator(method="rk4"), "Integrator.method", "rk4"),
        (lambda: Integrator(substeps=0), "Integrator.substeps", "0"),
        (lambda: Integrator(newton_chord_rate=1.0), "Integrator.newton_chord_rate", "1.0"),
        (lambda: Integrator(newton_chord_rate=-0.1), "Integrator.newton_chord_rate", "-0.1"),
        (lambda: SimConfig(medium="lava"), "SimConfig.medium", "lava"),
        (lambda: SimConfig(medium="ground", integrator=Integrator(method="sdirk2")), "ground", "sdirk2"),
        (lambda: SimConfig(medium="ground", integrator=Integrator(method="bdf2")), "ground", "bdf2"),
    ],
)
def test_impossible_parameters_name_field_value_and_range(make, field, value):
    with pytest.raises(ValueError) as err:
        make()
    msg = str(err.value)
    assert field in msg and value in msg
    assert any(w in msg for w in ("range", "must", "use", "allowed"))


def test_auto_method_is_sdirk2_in_water_and_backward_euler_on_the_ground():
    assert SimConfig().method == "sdirk2" and SimConfig(medium="none").method == "sdirk2"
    assert SimConfig(medium="ground").method == "backward_euler"
    chosen = Integrator(method="backward_euler")
    assert SimConfig(integrator=chosen).method == "backward_euler"


def test_derived_stiffnesses_follow_model_md():
    rod = Rod()
    assert rod.EA == pytest.approx(1.875e6 * np.pi * 0.055 * 0.05)
    assert rod.EI == pytest.approx(1.875e6 * np.pi * 0.055 * 0.05**3 / 4)
    soft = Rod(E_bend=1.87e4)
    assert soft.EA == rod.EA and soft.EI == pytest.approx(rod.EI * 1.87e4 / 1.875e6)


def test_default_yaml_files_are_exactly_the_dataclass_defaults():
    assert load_sim_config(CONFIGS / "eel.yaml") == SimConfig()
    assert load_sim_config(CONFIGS / "worm.yaml") == SimConfig(medium="ground")


def test_unknown_key_is_rejected_with_a_suggestion(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("rod:\n  edge_mas: 0.8\n")
    with pytest.raises(
        ConfigError, match=r"unknown key 'edge_mas' in bad.yaml.rod; did you mean 'edge_mass'"
    ):
        load_sim_config(path)


def test_malformed_yaml_names_the_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("rod:\n  N: 10\n  a: [0.05\n")
    with pytest.raises(ConfigError, match=r"broken.yaml.*not valid YAML at line \d+"):
        load_yaml(path)


def test_missing_file_and_wrong_types_are_explained(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        load_yaml(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match=r"Rod.N = 'ten' must be an integer"):
        from_dict(Rod, {"N": "ten"})
    with pytest.raises(ConfigError, match=r"Rod.edge_mass = -1.0 is outside the allowed range"):
        from_dict(Rod, {"edge_mass": -1})
    with pytest.raises(ConfigError, match="must be a mapping"):
        from_dict(SimConfig, {"rod": [1, 2]})


def test_scientific_notation_without_a_dot_reads_as_a_float(tmp_path):
    path = tmp_path / "soft.yaml"
    path.write_text("rod:\n  E_bend: 1.87e4\n  E: 2e6\n")
    cfg = load_sim_config(path)
    assert cfg.rod.E_bend == 1.87e4 and cfg.rod.E == 2e6


# --- presets ----------------------------------------------------------------------------------
def test_thesis_preset_is_the_sources_setting_and_overrides_win_field_by_field(tmp_path):
    from soft_snake_gym.config import load_preset, presets, with_preset

    assert "thesis" in presets()
    thesis = load_preset("thesis")  # set explicitly, whatever the package defaults become
    assert thesis["rod"]["damping_bend"] == 0.0 and thesis["rod"]["damping_stretch"] == 0.0
    assert thesis["rod"]["length_lag"] == 0.0
    assert thesis["fluid"]["added_mass"] == "kelasidi"
    assert thesis["integrator"]["method"] == "backward_euler"
    merged = with_preset(
        {"preset": "thesis", "rod": {"damping_bend": 2.5, "E_bend": 1e5}, "medium": "ground"}
    )
    assert "preset" not in merged and merged["medium"] == "ground"
    assert merged["rod"] == {"damping_bend": 2.5, "damping_stretch": 0.0, "length_lag": 0.0, "E_bend": 1e5}
    assert merged["fluid"] == {"added_mass": "kelasidi"}
    # a whole dataclass given explicitly replaces the preset's section
    assert with_preset({"preset": "thesis", "fluid": Fluid(rho=1025.0)})["fluid"] == Fluid(rho=1025.0)
    assert with_preset({"preset": None, "rod": {"N": 12}}) == {"rod": {"N": 12}}
    # the SimConfig loader takes a preset key too
    path = tmp_path / "thesis_soft.yaml"
    path.write_text("preset: thesis\nrod:\n  E_bend: 1.87e4\n")
    cfg = load_sim_config(path)
    assert cfg.rod == Rod(E_bend=1.87e4, damping_bend=0.0, damping_stretch=0.0, length_lag=0.0)
    assert cfg.fluid == Fluid(added_mass="kelasidi")


def test_shipped_presets_hold_only_valid_simulator_sections():
    from soft_snake_gym.config import PRESET_SECTIONS, load_preset, presets

    for name in presets():
        data = load_preset(name)
        assert set(data) <= set(PRESET_SECTIONS)
        from_dict(SimConfig, data)  # every value is valid


@pytest.mark.parametrize(
    ("name", "message"),
    [
        (
            "thesiss",
            r"preset = 'thesiss' is unknown \(did you mean 'thesis'\?\); available presets: .*thesis",
        ),
        ("nope", r"preset = 'nope' is unknown; available presets: .*thesis"),
        (3, r"preset = 3 is unknown; available presets"),
    ],
)
def test_unknown_preset_lists_the_available_ones(tmp_path, name, message):
    from soft_snake_gym.config import with_preset

    with pytest.raises(ConfigError, match=message):
        with_preset({"preset": name})
    path = tmp_path / "bad.yaml"
    path.write_text(f"preset: {name}\n")
    with pytest.raises(ConfigError, match="bad.yaml: " + message):
        load_sim_config(path)


def test_presets_and_configs_are_shipped_as_package_data():
    import fnmatch

    tomllib = pytest.importorskip("tomllib")
    root = Path(__file__).resolve().parents[1]
    globs = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    files = sorted(p for p in (root / "soft_snake_gym" / "configs").rglob("*") if p.is_file())
    assert {p.parent.name for p in files} == {"env", "policy", "algorithm", "presets"}
    assert files
    for f in files:
        rel = f.relative_to(root / "soft_snake_gym").as_posix()
        assert any(fnmatch.fnmatch(rel, g) for g in globs["soft_snake_gym"]), rel
