"""The environments' constructor keywords, validated.

The settings both environments share, domain randomization, and how a preset, a YAML config and
explicit keywords combine into one settings object.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from soft_snake_gym.config import ConfigError, config_path, from_dict, load_yaml, with_preset
from soft_snake_gym.params import (
    LENGTH_LAG_MAX,
    Fluid,
    Ground,
    Integrator,
    Rod,
    SimConfig,
    check_number,
    plain_number,
)

__all__ = ["BaseSettings", "Randomization", "resolve_settings"]


@dataclass(frozen=True)
class Randomization:
    """Per-episode physics randomization.

    Each field is ``None`` (not randomized) or a range ``[low, high]`` from which the value is drawn
    uniformly at every ``reset``.

    Fields map onto :class:`~soft_snake_gym.params.Rod` (``E``, ``E_bend``, ``damping_bend``, ``damping_stretch``,
    ``length_lag``: at most 10 s, and only where the env drives rest lengths, on the ground),
    :class:`~soft_snake_gym.params.Fluid` (``rho``, ``C_f``, ``C_D``, ``C_A``) and
    :class:`~soft_snake_gym.params.Ground` (``mu_s``, ``mu_d``). The draws happen in field order
    from ``env.np_random``. The env rejects ranges whose draws could break a constraint of the
    parameters (``mu_d <= mu_s``) and parameters its medium does not use (``mu_s`` in water,
    ``C_D`` on the ground).
    """

    E: tuple[float, float] | None = None
    E_bend: tuple[float, float] | None = None
    damping_bend: tuple[float, float] | None = None
    damping_stretch: tuple[float, float] | None = None
    length_lag: tuple[float, float] | None = None
    rho: tuple[float, float] | None = None
    C_f: tuple[float, float] | None = None
    C_D: tuple[float, float] | None = None
    C_A: tuple[float, float] | None = None
    mu_s: tuple[float, float] | None = None
    mu_d: tuple[float, float] | None = None

    _SECTIONS: ClassVar[dict[str, str]] = {
        "E": "rod",
        "E_bend": "rod",
        "damping_bend": "rod",
        "damping_stretch": "rod",
        "length_lag": "rod",
        "rho": "fluid",
        "C_f": "fluid",
        "C_D": "fluid",
        "C_A": "fluid",
        "mu_s": "ground",
        "mu_d": "ground",
    }

    def __post_init__(self) -> None:
        """Check that each given range is a valid pair [low, high] of finite numbers; store it as a tuple."""
        for f in dataclasses.fields(self):
            rng = getattr(self, f.name)
            if rng is None:
                continue
            try:
                rng = tuple(plain_number(v) for v in rng)
            except TypeError:
                rng = (None,)
            if len(rng) != 2 or not all(v is not None and math.isfinite(v) for v in rng):
                raise ValueError(
                    f"Randomization.{f.name} = {getattr(self, f.name)!r} must be a pair [low, high] "
                    "of finite numbers"
                )
            object.__setattr__(self, f.name, rng)
            lo, hi = rng
            positive = f.name in ("E", "E_bend")
            if lo > hi or lo < 0 or (positive and lo <= 0):
                allowed = "0 < low <= high" if positive else "0 <= low <= high"
                raise ValueError(
                    f"Randomization.{f.name} = {list(rng)!r} is not a valid range: need {allowed}"
                )
            if f.name == "length_lag" and hi > LENGTH_LAG_MAX:
                raise ValueError(
                    f"Randomization.length_lag = {list(rng)!r} reaches past Rod.length_lag's range "
                    f"[0, {LENGTH_LAG_MAX:g}] s; keep high <= {LENGTH_LAG_MAX:g}"
                )

    @functools.cached_property
    def enabled(self) -> bool:
        """True if any parameter is randomized (asked at every reset: computed once)."""
        return any(getattr(self, f.name) is not None for f in dataclasses.fields(self))

    def draw(self, rng: np.random.Generator, base: SimConfig) -> tuple[SimConfig, dict[str, float]]:
        """Draw one configuration around ``base``; returns it and the drawn values."""
        drawn: dict[str, float] = {}
        sections: dict[str, dict[str, float]] = {"rod": {}, "fluid": {}, "ground": {}}
        for f in dataclasses.fields(self):
            bounds = getattr(self, f.name)
            if bounds is None:
                continue
            value = float(rng.uniform(bounds[0], bounds[1]))
            drawn[f.name] = value
            sections[self._SECTIONS[f.name]][f.name] = value
        config = dataclasses.replace(
            base,
            rod=dataclasses.replace(base.rod, **sections["rod"]),
            fluid=dataclasses.replace(base.fluid, **sections["fluid"]),
            ground=dataclasses.replace(base.ground, **sections["ground"]),
        )
        return config, drawn

    def check(self, medium: str, ground: Ground, where: str) -> None:
        """Raise ``ConfigError`` if a randomized parameter is useless or could give ``mu_d > mu_s``.

        Useless: it has no effect in ``medium``. The ``mu_d > mu_s`` check takes ``ground`` for the
        values not randomized.
        """
        unused = {"water": "ground", "ground": "fluid"}.get(medium)
        useless = [
            f.name
            for f in dataclasses.fields(self)
            if getattr(self, f.name) is not None and self._SECTIONS[f.name] == unused
        ]
        if useless:
            raise ConfigError(
                f"{where}.randomize: {', '.join(useless)} {'has' if len(useless) == 1 else 'have'} no "
                f"effect in the {medium} ({unused} parameters); remove "
                f"{'it' if len(useless) == 1 else 'them'}"
            )
        if medium == "water" and self.length_lag is not None:
            raise ConfigError(
                f"{where}.randomize: length_lag has no effect in the water (the swimming envs drive "
                "no rest lengths); remove it"
            )
        if medium != "ground":
            return
        mu_s_low = ground.mu_s if self.mu_s is None else self.mu_s[0]
        mu_d_high = ground.mu_d if self.mu_d is None else self.mu_d[1]
        if mu_d_high > mu_s_low:
            mu_s = f"randomize.mu_s low {mu_s_low!r}" if self.mu_s else f"ground.mu_s = {mu_s_low!r}"
            mu_d = f"randomize.mu_d high {mu_d_high!r}" if self.mu_d else f"ground.mu_d = {mu_d_high!r}"
            raise ConfigError(
                f"{where}: {mu_d} exceeds {mu_s}, so some draws would have kinetic friction above "
                "static friction; keep every mu_d draw at or below every mu_s draw "
                "(randomize.mu_d high <= randomize.mu_s low)"
            )


@dataclass(frozen=True)
class BaseSettings:
    """Constructor keywords shared by both environments (see the env docstrings)."""

    rod: Rod = Rod()
    fluid: Fluid = Fluid()
    ground: Ground = Ground()
    integrator: Integrator = Integrator()
    dt: float | None = None
    forward_reward_weight: float = 1.0
    energy_cost_weight: float = 1e-3
    ctrl_cost_weight: float = 1e-2
    failure_cost: float = 10.0
    reset_noise_scale: float = 0.01
    goal_direction: float = 0.0
    max_observed_speed: float = 2.0
    randomize: Randomization = field(default_factory=Randomization)

    def __post_init__(self) -> None:
        """Make numpy scalars Python numbers; check the values (``dt`` a multiple of ``integrator.h``)."""
        cls = type(self).__name__
        for f in dataclasses.fields(self):  # numpy scalars become Python numbers
            number = plain_number(getattr(self, f.name))
            if number is not None and type(number) is not type(getattr(self, f.name)):
                object.__setattr__(self, f.name, number)
        if self.dt is not None:
            check_number(f"{cls}.dt", self.dt, 0.0, lo_open=True)
            ratio = self.dt / self.integrator.h
            if ratio < 0.999 or abs(ratio - round(ratio)) > 1e-6 * ratio:
                raise ValueError(
                    f"{cls}.dt = {self.dt!r} must be a positive integer multiple of the integrator "
                    f"step integrator.h = {self.integrator.h!r}"
                )
        for name in ("forward_reward_weight", "goal_direction"):
            check_number(f"{cls}.{name}", getattr(self, name))
        for name in ("energy_cost_weight", "ctrl_cost_weight", "failure_cost", "reset_noise_scale"):
            check_number(f"{cls}.{name}", getattr(self, name), 0.0)
        check_number(f"{cls}.max_observed_speed", self.max_observed_speed, 0.0, lo_open=True)


def resolve_settings(
    settings_cls: type, medium: str, config: str | Path | None, kwargs: dict, label: str | None = None
) -> Any:
    """Settings from a preset, a YAML file and explicit keywords, each overriding the one before.

    The preset is named, and the YAML file holds constructor keywords.

    A ``medium`` key in the file (as in the shipped ``eel`` config) is accepted if it names this
    environment's medium. A ``preset`` key (in the file or the keywords) lays that preset's
    simulator sections beneath the rest, field by field
    (:func:`soft_snake_gym.config.with_preset`). Unknown keys are rejected with the closest
    valid name.
    """
    data: dict[str, Any] = {}
    where = label or settings_cls.__name__
    if config is not None:
        data = dict(load_yaml(config_path(config, "env")))
        where = Path(config).name
        file_medium = data.pop("medium", medium)
        if file_medium != medium:
            raise ConfigError(
                f"{where} sets medium = {file_medium!r}, but this environment runs in {medium!r}; "
                f"remove the key or set it to {medium!r}"
            )
    data.update(kwargs)
    if config is not None and kwargs:
        where = f"{where} with keyword overrides"
    return from_dict(settings_cls, with_preset(data, where), where=where)
