"""Loading and validating site configurations against the JSON schemas.

A site configuration is one YAML file (``config/sites/<site>.yaml``); the global
``config/config.yaml`` names the default site. The schema lives in
``config/schema/site.schema.yaml`` with one file per stage under
``config/schema/stages/<stage>.schema.yaml``, so each stage owns its keys.

Errors are one line that names the file and the offending key path, e.g.::

    config/sites/x.yaml: tether.kite.area_m2: 'big' is not of type 'number'
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Iterable, Mapping

import jsonschema
import yaml

from kitegully import InputError

SCHEMA_DIR = Path(__file__).resolve().parents[2] / "config" / "schema"


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping, raising :class:`InputError` naming the file on failure."""
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise InputError(f"{path}: not valid YAML{where}: {getattr(exc, 'problem', exc)}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(f"{path}: top level must be a mapping of keys, got {type(data).__name__}")
    return data


def load_schema(schema_dir: str | Path = SCHEMA_DIR) -> dict[str, Any]:
    """Assemble the full schema: the site schema plus every stage schema.

    Each ``stages/<name>.schema.yaml`` becomes ``properties.<name>`` of the top level.
    """
    schema_dir = Path(schema_dir)
    schema = load_yaml(schema_dir / "site.schema.yaml")
    props = schema.setdefault("properties", {})
    for stage_file in sorted((schema_dir / "stages").glob("*.schema.yaml")):
        name = stage_file.name.removesuffix(".schema.yaml")
        props[name] = load_yaml(stage_file)
    return schema


def _strip_required(schema: Any) -> Any:
    """Copy of ``schema`` without any ``required`` lists (for partial files)."""
    if isinstance(schema, dict):
        return {k: _strip_required(v) for k, v in schema.items() if k != "required"}
    if isinstance(schema, list):
        return [_strip_required(v) for v in schema]
    return schema


def _format_error(error: jsonschema.ValidationError, source: str) -> str:
    path = ".".join(str(p) for p in error.absolute_path)
    if error.validator == "additionalProperties":
        extra = [k for k in error.instance if k not in error.schema.get("properties", {})]
        key = ".".join(filter(None, [path, extra[0] if extra else ""]))
        allowed = ", ".join(sorted(error.schema.get("properties", {})))
        return f"{source}: unknown key '{key}' (allowed here: {allowed})"
    where = path or "(top level)"
    return f"{source}: {where}: {error.message}"


def _first_error(schema: Mapping, data: Mapping) -> jsonschema.ValidationError | None:
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(data), key=lambda e: (len(e.absolute_path), str(e.absolute_path)))
    return errors[0] if errors else None


def validate_config(
    config: Mapping[str, Any],
    sources: Iterable[str | Path] = (),
    schema_dir: str | Path = SCHEMA_DIR,
) -> dict[str, Any]:
    """Validate a merged configuration and the files it came from.

    Each source file is first checked on its own (types and unknown keys, without
    ``required``) so the error can name the file that is wrong; then the merged
    configuration is checked completely. Defaults declared in the schema are not
    injected: every value a method uses is written in the site file.

    Parameters
    ----------
    config
        The merged configuration (what Snakemake's ``config`` holds).
    sources
        The YAML files that were merged into ``config``, in load order.
    schema_dir
        Folder holding ``site.schema.yaml`` and ``stages/``.

    Returns
    -------
    dict
        A deep copy of ``config``.

    Raises
    ------
    InputError
        One line naming the file and the offending key.
    """
    schema = load_schema(schema_dir)
    partial = _strip_required(schema)
    for source in sources:
        error = _first_error(partial, load_yaml(source))
        if error is not None:
            raise InputError(_format_error(error, str(source)))
    error = _first_error(schema, config)
    if error is not None:
        names = ", ".join(str(s) for s in sources) or "configuration"
        raise InputError(_format_error(error, names))
    _check_site_crs(config, sources)
    return copy.deepcopy(dict(config))


def config_section(cfg: Any, where: str, keys: Iterable[str], optional: Iterable[str] = ()) -> Mapping[str, Any]:
    """Check that a config section holds exactly ``keys`` (plus any of ``optional``).

    Used by the ``from_config`` classmethods of the stage parameter dataclasses, so a
    section built by hand (tests, benchmarks) is held to the same keys as the schema.

    Parameters
    ----------
    cfg
        The section (a mapping).
    where
        Its key path for messages, e.g. ``"georef.qa"``.
    keys, optional
        Required and optional key names.

    Returns
    -------
    Mapping
        ``cfg`` itself.

    Raises
    ------
    InputError
        Naming the section and the first missing or unknown key.
    """
    if not isinstance(cfg, Mapping):
        raise InputError(f"{where}: must be a mapping of keys, got {type(cfg).__name__}")
    keys = list(keys)
    allowed = set(keys) | set(optional)
    missing = [k for k in keys if k not in cfg]
    if missing:
        raise InputError(f"{where}: missing key '{missing[0]}'")
    unknown = sorted(str(k) for k in cfg if k not in allowed)
    if unknown:
        raise InputError(f"{where}: unknown key '{unknown[0]}' (allowed here: {', '.join(sorted(allowed))})")
    return cfg

def checked_number(cfg: Mapping[str, Any], key: str, where: str, low: float = 0.0, strict: bool = True) -> Any:
    """Return ``cfg[key]`` after checking that it is a number above (or at least) ``low``.

    The one bound check of the stages' ``from_config`` classmethods, so every section
    words the same mistake the same way.

    Parameters
    ----------
    cfg
        The config section.
    key
        The key to check.
    where
        The section's key path for the message, e.g. ``"dense.orthophoto"``.
    low
        The bound.
    strict
        True: the value must be above ``low`` (``low`` = 0 reads "positive"); False: at least ``low``.

    Returns
    -------
    int or float
        The value as given.

    Raises
    ------
    InputError
        ``"<where>.<key>: must be positive, got <value>"`` (or "above"/"at least").
    """
    v = cfg[key]
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and (v > low if strict else v >= low)
    if not ok:
        bound = "positive" if strict and low == 0 else f"{'above' if strict else 'at least'} {low:g}"
        raise InputError(f"{where}.{key}: must be {bound}, got {v!r}")
    return v


def checked_choice(cfg: Mapping[str, Any], key: str, where: str, allowed: Iterable[Any]) -> Any:
    """Return ``cfg[key]`` after checking that it is one of ``allowed``.

    Parameters
    ----------
    cfg, key, where
        As for :func:`checked_number`.
    allowed
        The accepted values.

    Returns
    -------
    Any
        The value as given.

    Raises
    ------
    InputError
        ``"<where>.<key>: must be one of a, b, got <value>"``.
    """
    allowed = tuple(allowed)
    if cfg[key] not in allowed:
        raise InputError(f"{where}.{key}: must be one of {', '.join(map(str, allowed))}, got {cfg[key]!r}")
    return cfg[key]


def _check_site_crs(config: Mapping[str, Any], sources: Iterable[str | Path]) -> None:
    """``site.crs`` must be a projected CRS in metres; the error names the file that set it."""
    from kitegully.inputs.crs import site_crs  # pyproj is only needed once the schema passed

    crs = config.get("site", {}).get("crs")
    if crs is None:
        return
    setters = [str(s) for s in sources if "crs" in (load_yaml(s).get("site") or {})]
    where = setters[-1] if setters else "configuration"
    site_crs(crs, f"{where}: site.crs")


def merge_config(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``over`` on ``base``, mappings merged key by key, as Snakemake merges several
    ``--configfile`` files (an override file names only the keys that differ)."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge_config(out[k], v) if isinstance(v, Mapping) and isinstance(out.get(k), Mapping) else v
    return out


def main(argv: list[str] | None = None) -> int:
    """``python -m kitegully.config SITE.yaml ...``: validate config files, print one line."""
    import sys

    files = list(argv if argv is not None else sys.argv[1:])
    base = Path(__file__).resolve().parents[2] / "config" / "config.yaml"
    try:
        merged: dict[str, Any] = load_yaml(base)
        files = files or [merged["default_site"]]
        for f in files:
            merged = merge_config(merged, load_yaml(f))
        validate_config(merged, sources=files)
    except InputError as exc:
        print(f"Invalid configuration: {exc}", file=sys.stderr)
        return 1
    print(f"{', '.join(files) or base}: valid")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
