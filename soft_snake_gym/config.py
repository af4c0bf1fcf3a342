"""The one config loader: YAML files map one to one onto frozen dataclasses.

``load_yaml`` reads a file and explains what is wrong with it (missing, malformed, not a
mapping); ``from_dict`` builds a dataclass, recursing into nested dataclass fields and
rejecting unknown keys with the closest valid name; ``with_preset`` lays a named preset
(a YAML file of simulator sections shipped in ``soft_snake_gym/configs/presets``) beneath a
mapping. Nothing is ``eval``'d.

:func:`parse_value` and :func:`parse_assignments` are the one ``key=value`` grammar of the
command line and of policy specs (``--env-kwarg``, ``--hyperparams``, ``pid:alpha=pi/6``), and
:func:`config_path` finds a config shipped in ``soft_snake_gym/configs/{env,policy,algorithm}``
by name (``"softeel"``) or takes a path.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
import re
import types
import typing
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TypeVar

import yaml

from soft_snake_gym.params import SimConfig, plain_number

__all__ = [
    "CONFIG_KINDS",
    "ConfigError",
    "config_path",
    "load_yaml",
    "parse_assignments",
    "parse_value",
    "shipped_configs",
    "from_dict",
    "to_dict",
    "load_sim_config",
    "PRESET_SECTIONS",
    "presets",
    "load_preset",
    "with_preset",
]

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration file or mapping that cannot be turned into parameters."""


class _Loader(yaml.SafeLoader):
    """SafeLoader that reads ``1e6`` as a float and refuses duplicate keys.

    It reads ``1e6`` and ``2e-3`` as floats (YAML 1.1 wants ``1.0e+6``) and refuses a key given
    twice in one mapping (PyYAML would keep the last silently).
    """

    def construct_mapping(self, node, deep=False):
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.setdefault(key, key_node.start_mark)
            except TypeError:  # an unhashable key: PyYAML's own error follows
                continue
            if first is not key_node.start_mark:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f"duplicate key {key!r} (first given on line {first.line + 1})",
                    key_node.start_mark,
                )
        return super().construct_mapping(node, deep=deep)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML file whose top level is a mapping.

    Raises:
        ConfigError: the file is missing, is not valid YAML, or is not a mapping.
    """
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"config file {str(path)!r} is a folder; give the path of a YAML file")
    if not path.is_file():
        raise ConfigError(f"config file {str(path)!r} does not exist; check the path")
    try:
        data = yaml.load(path.read_text(), Loader=_Loader)  # noqa: S506 - SafeLoader subclass
    except yaml.YAMLError as err:
        where = ""
        mark = getattr(err, "problem_mark", None)
        if mark is not None:
            where = f" at line {mark.line + 1}, column {mark.column + 1}"
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise ConfigError(f"config file {str(path)!r} is not valid YAML{where}: {problem}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"config file {str(path)!r} must hold a mapping of keys to values at its top "
            f"level, not a {type(data).__name__}"
        )
    return data


def _unknown_key_message(where: str, key: str, valid: list[str]) -> str:
    close = difflib.get_close_matches(str(key), valid, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else "."
    return f"unknown key {key!r} in {where}{hint} Valid keys: {', '.join(valid)}"


def _coerce(value: Any, hint: Any, where: str) -> Any:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(hint)
        if value is None and type(None) in options:
            return None
        last: Exception | None = None
        for option in options:
            if option is type(None):
                continue
            try:
                return _coerce(value, option, where)
            except ConfigError as err:
                last = err
        raise last if last else ConfigError(f"{where}: unsupported value {value!r}")
    if dataclasses.is_dataclass(hint):
        return from_dict(hint, value, where)
    if origin is typing.Literal:
        allowed = typing.get_args(hint)
        if value not in allowed:
            raise ConfigError(f"{where} = {value!r} must be one of {list(allowed)}")
        return value
    if hint is float:
        number = plain_number(value)
        if number is None:
            raise ConfigError(f"{where} = {value!r} must be a number")
        return float(number)
    if hint is int:
        number = plain_number(value, integer=True)
        if number is None:
            raise ConfigError(f"{where} = {value!r} must be an integer")
        return number
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where} = {value!r} must be true or false")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} = {value!r} must be a string")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where} = {value!r} must be a list")
        args = typing.get_args(hint)
        inner = args[0] if args else Any
        return tuple(_coerce(v, inner, f"{where}[{i}]") for i, v in enumerate(value))
    return value


def from_dict(cls: type[T], data: Any, where: str | None = None) -> T:
    """Build dataclass ``cls`` from a mapping, recursing into nested dataclasses.

    Raises:
        ConfigError: unknown keys, wrong types, or values the dataclass rejects.
    """
    where = where or cls.__name__
    if isinstance(data, cls):
        return data
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{where} must be a mapping of keys to values, got {data!r}")
    hints = typing.get_type_hints(cls)
    valid = [f.name for f in dataclasses.fields(cls) if f.init]
    retired = set(inspect.signature(cls).parameters) - set(valid)  # InitVars that explain themselves
    kwargs = {}
    for key, value in data.items():
        if key not in valid and key not in retired:  # a retired key's own check explains it
            raise ConfigError(_unknown_key_message(where, key, valid))
        try:
            kwargs[key] = _coerce(value, hints[key], f"{where}.{key}")
        except ConfigError as err:
            # a wrong type at this key: the class's own message names the range; an error from
            # inside a nested section already says what is wrong there
            here = str(err).startswith(f"{where}.{key} = ")
            raise ConfigError((here and _with_range(cls, key, value, where)) or str(err)) from None
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise ConfigError(str(err)) from None


def _with_range(cls: type, key: str, value: Any, where: str) -> str | None:
    """The dataclass's own message for a value of the wrong type, under the name ``where.key``.

    The message names the allowed range (``Rod.E = 'abc' must be a number in (0.0, inf)``); None if
    the class has no check of its own for ``key``.
    """
    try:
        cls(**{key: value})
    except (ValueError, TypeError) as err:
        own = f"{cls.__name__}.{key} = "
        message = str(err)
        if message.startswith(own):
            return f"{where}.{key} = {message[len(own) :]}"
    return None


def to_dict(obj: Any) -> dict[str, Any]:
    """The plain mapping of a (nested) dataclass, ready for ``yaml.safe_dump``."""
    return dataclasses.asdict(obj)


def load_sim_config(path: str | Path) -> SimConfig:
    """Load a :class:`SimConfig` from a YAML file.

    Sections rod, medium, fluid, ground, integrator; any may be left out for its default; a
    ``preset`` key lays that preset beneath the file's sections, see :func:`with_preset`.
    """
    where = Path(path).name
    return from_dict(SimConfig, with_preset(load_yaml(path), where), where=where)


# --- key=value: the one grammar ----------------------------------------------------------------
def _number(text: str) -> int | float | None:
    """``text`` as a number.

    An integer or float literal (``2``, ``0.5``, ``1e4``, ``inf``) or a product/quotient of such
    numbers and ``pi`` (``pi/6``, ``2*pi/3``); None if it is not one.
    """
    try:
        return int(text) if text.lstrip("+-").isdigit() else float(text)
    except ValueError:
        pass
    value, op = 1.0, "*"
    factors = text.replace("/", " / ").replace("*", " * ").split()
    for i, factor in enumerate(factors):
        if factor in ("*", "/"):
            op = factor
            continue
        try:
            num = math.pi if factor.lower() == "pi" else float(factor)
        except ValueError:
            return None
        value = num if i == 0 else (value * num if op == "*" else value / num)
    return value if factors else None


def parse_value(text: str) -> Any:
    """The value of one ``key=value`` item, in the grammar every ``key=value`` of the package uses.

    In order: a number (``0.5``, ``1e4``, ``inf``, ``pi``, ``pi/6``, ``2*pi/3``); else a YAML
    value read with the package's loader (``true``, ``null``, ``[128, 128]``, ``{a: 1}``; an
    empty value is ``None``); else the text itself, stripped (``pacemaker``). The text never
    fails to parse: whether the value fits its key is the receiving dataclass's check.
    """
    s = text.strip()
    number = _number(s)
    if number is not None:
        return number
    try:
        value = yaml.load(s, Loader=_Loader)  # noqa: S506 - SafeLoader subclass
    except yaml.YAMLError:
        return s
    return s if isinstance(value, str) else value


def parse_assignments(
    items: Iterable[str] | None, usage: str, nested: bool = True, sep: str | None = None
) -> dict[str, Any]:
    """``key=value`` items as a mapping, values by :func:`parse_value`.

    Args:
        items: the items (``["dt=0.02", "rod.E_bend=1.87e4"]``), or None.
        usage: the error message for an item that is not ``key=value``, with ``{item}`` where
            the item goes, quoted (``"--env-kwarg {item} is not key=value; write e.g. ..."``).
        nested: dotted keys build nested sections (``rod.E_bend=1`` -> ``{"rod": {"E_bend": 1}}``);
            if False a dotted key stays one key.
        sep: if given, each item is first split at ``sep`` (``","`` for ``pid:alpha=0.5,omega=2``);
            empty pieces are skipped.

    Raises:
        ConfigError: an item without ``=`` or with an empty key.
    """
    out: dict[str, Any] = {}
    pieces = [p for item in items or [] for p in (item.split(sep) if sep else [item])]
    for item in pieces:
        if sep is not None:
            item = item.strip()
            if not item:
                continue
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ConfigError(usage.replace("{item}", repr(item)))
        parts = key.strip().split(".") if nested else [key.strip()]
        node = out
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = parse_value(value)
    return out


# --- shipped configs ----------------------------------------------------------------------------
CONFIG_DIR = Path(__file__).parent / "configs"

#: The kinds of config shipped in ``soft_snake_gym/configs/<kind>/``: env keywords
#: (``gym.make(id, config=...)``), a baseline's parameters (``--policy-config``),
#: hyperparameters keyed by env id (``soft-snake train --config``) and physics presets
#: (``preset=``, :func:`load_preset`).
CONFIG_KINDS = ("env", "policy", "algorithm", "presets")


def shipped_configs(kind: str) -> dict[str, Path]:
    """Name -> file of the configs of ``kind`` (one of :data:`CONFIG_KINDS`) in the package."""
    if kind not in CONFIG_KINDS:
        raise ValueError(f"config kind {kind!r} must be one of {', '.join(CONFIG_KINDS)}")
    folder = CONFIG_DIR / kind
    return {p.stem: p for p in sorted(folder.glob("*.y*ml")) if p.suffix in (".yaml", ".yml")}


def config_path(config: str | Path, kind: str) -> Path:
    """The file of ``config``: a shipped config of ``kind`` by name (``"softeel"``), or a path.

    A name is anything without a folder separator or a ``.yaml``/``.yml`` suffix that is not an
    existing file; everything else is taken as a path (whose absence :func:`load_yaml` reports).

    Raises:
        ConfigError: a name that is no shipped config of ``kind`` (the message lists them).
    """
    path = Path(config)
    text = str(config)
    if (
        isinstance(config, Path)
        or path.suffix in (".yaml", ".yml")
        or "/" in text
        or "\\" in text
        or path.exists()
    ):
        return path
    shipped = shipped_configs(kind)
    if text in shipped:
        return shipped[text]
    close = difflib.get_close_matches(text, list(shipped), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ConfigError(
        f"{kind} config {text!r} is neither a file nor a config shipped with the package{hint}; "
        f"shipped {kind} configs: {', '.join(shipped)}; or give the path of a YAML file"
    )


# --- presets ------------------------------------------------------------------------------------
#: The sections a preset may set: those of :class:`SimConfig` that describe the physics.
PRESET_SECTIONS = ("rod", "fluid", "ground", "integrator")


def presets() -> list[str]:
    """Names of the presets shipped with the package (``thesis``: the sources' setting)."""
    return list(shipped_configs("presets"))


def load_preset(name: str) -> dict[str, dict[str, Any]]:
    """The sections of preset ``name``: a mapping of :data:`PRESET_SECTIONS` to field values.

    Raises:
        ConfigError: ``name`` is not a shipped preset (the message lists them), or the preset
            file holds anything but simulator sections.
    """
    available = presets()
    if not isinstance(name, str) or name not in available:
        close = difflib.get_close_matches(str(name), available, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(f"preset = {name!r} is unknown{hint}; available presets: {', '.join(available)}")
    data = load_yaml(shipped_configs("presets")[name])
    for key, value in data.items():
        if key not in PRESET_SECTIONS or not isinstance(value, dict):
            raise ConfigError(
                f"preset {name!r} sets {key!r}: a preset holds only the sections "
                f"{', '.join(PRESET_SECTIONS)}, each a mapping"
            )
    return data


def with_preset(data: dict[str, Any], where: str = "the configuration") -> dict[str, Any]:
    """``data`` without its ``preset`` key, laid over that preset's sections.

    Keys given in ``data`` win field by field: ``{"preset": "thesis", "rod": {"E_bend": 1e5}}``
    keeps the preset's rod damping and sets ``E_bend``. A section given as a dataclass (a
    whole :class:`~soft_snake_gym.params.Rod`, say) replaces the preset's section. Without a
    ``preset`` key (or with ``preset: null``) ``data`` is returned unchanged.

    Raises:
        ConfigError: an unknown preset name (see :func:`load_preset`).
    """
    if data.get("preset") is None:
        return {k: v for k, v in data.items() if k != "preset"}
    data = dict(data)
    name = data.pop("preset")
    try:
        merged: dict[str, Any] = load_preset(name)
    except ConfigError as err:
        raise ConfigError(f"{where}: {err}") from None
    for key, value in data.items():
        base = merged.get(key)
        merged[key] = {**base, **value} if isinstance(base, dict) and isinstance(value, dict) else value
    return merged
