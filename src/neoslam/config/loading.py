"""Loading: defaults < YAML file (`--config`) < NEOSLAM_<SECTION>__<FIELD> environment variables."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from neoslam.config.system import NeoSLAMConfig
from neoslam.errors import ConfigError, InputError
from neoslam.text import load_yaml, read_yaml

__all__ = ["ENV_PREFIX", "config_values", "describe_validation_error", "dump_config", "load_config", "merge_settings"]

ENV_PREFIX = "NEOSLAM_"
ENV_NESTED_DELIMITER = "__"


def _env_overrides(environ: dict[str, str]) -> dict[str, Any]:
    """Nested dict from NEOSLAM_SECTION__FIELD[__FIELD] variables; values parsed as YAML scalars."""
    overrides: dict[str, Any] = {}
    for key, raw in sorted(environ.items()):
        if not key.startswith(ENV_PREFIX) or ENV_NESTED_DELIMITER not in key:
            continue  # NEOSLAM_DATA and friends are not configuration
        path = key[len(ENV_PREFIX) :].lower().split(ENV_NESTED_DELIMITER)
        node = overrides
        for part in path[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):  # NEOSLAM_A__B=1 and NEOSLAM_A__B__C=2: B cannot be both
                raise ConfigError(f"environment variable {key}: {part} is set as a value by another variable")
        node[path[-1]] = _parse_scalar(raw)
    return overrides


def _parse_scalar(raw: str) -> Any:
    """A YAML scalar or list ("0.3", "true", "[36, 36, 36]"); text that is not YAML stays a string, so that
    validation names the field instead of the YAML parser failing."""
    try:
        return load_yaml(raw) if raw.strip() else raw
    except yaml.YAMLError:
        return raw


def merge_settings(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """`override` over `base`, section by section (nested mappings merged, other values replaced)."""
    merged = dict(base)
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = merge_settings(merged[key], value)
        else:
            merged[key] = value
    return merged


def describe_validation_error(error: ValidationError) -> str:
    """The first problem of a validation as `section.field: reason (got value)`, for a one-line message."""
    first = error.errors()[0]
    where = ".".join(str(part) for part in first["loc"])
    reason = first["msg"].removeprefix("Value error, ")
    given = first.get("input")
    if isinstance(given, bool | int | float | str) and len(repr(given)) <= 40 and first["type"] != "extra_forbidden":
        reason += f" (got {given!r})"
    return f"{where}: {reason}" if where else reason


def _variable_for(location: tuple[Any, ...], environ: dict[str, str]) -> str:
    """The NEOSLAM_* variable that set the value at `location` (or under it: NEOSLAM_FOO__BAR for an unknown
    section foo), as the user spelled it."""
    wanted = tuple(str(part) for part in location)
    for key in sorted(environ):
        if not key.startswith(ENV_PREFIX) or ENV_NESTED_DELIMITER not in key:
            continue
        path = tuple(key[len(ENV_PREFIX) :].lower().split(ENV_NESTED_DELIMITER))
        if wanted[: len(path)] == path or path[: len(wanted)] == wanted:
            return key
    return ENV_PREFIX + ENV_NESTED_DELIMITER.join(wanted).upper()


def _read_yaml_mapping(path: Path) -> dict[str, Any]:
    """A config file's sections: one error naming the file (and the line, where YAML knows it) otherwise."""
    loaded = read_yaml(path, missing="config file not found") or {}
    if not isinstance(loaded, dict):
        raise InputError(path, "a config file must hold a mapping of sections")
    return loaded


def config_values(path: Path | None = None, environ: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The settings a YAML file and then NEOSLAM_* environment variables give over the defaults, as a mapping
    (checked: a bad value is a ConfigError naming the file or the variable), for callers that merge more on top."""
    values = _read_yaml_mapping(path) if path is not None else {}
    variables = dict(os.environ if environ is None else environ)
    merged = merge_settings(values, _env_overrides(variables))
    try:
        NeoSLAMConfig.model_validate(values)
    except ValidationError as error:
        raise ConfigError(f"{path or 'configuration'}: {describe_validation_error(error)}") from None
    try:
        NeoSLAMConfig.model_validate(merged)
    except ValidationError as error:
        variable = _variable_for(error.errors()[0]["loc"], variables)
        raise ConfigError(f"environment variable {variable}: {describe_validation_error(error)}") from None
    return merged


def load_config(path: Path | None = None, environ: Mapping[str, str] | None = None) -> NeoSLAMConfig:
    """Defaults, then the YAML file, then NEOSLAM_* environment variables."""
    return NeoSLAMConfig.model_validate(config_values(path, environ))


def dump_config(config: NeoSLAMConfig) -> str:
    """The resolved configuration as YAML, sections in declaration order."""
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False)
