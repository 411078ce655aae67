"""``params.yaml``: every knob of the pipeline, flat and literal (the paper's values are
the defaults). Commands read their section from it; command-line options override."""

from __future__ import annotations

from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any, TypeVar

import yaml

from hsp.errors import HspError

DEFAULT_PARAMS = Path("params.yaml")
C = TypeVar("C")


def load_params(path: Path | None = None) -> dict[str, Any]:
    """The parsed params file; ``{}`` when the default file is absent."""
    p = Path(path) if path else DEFAULT_PARAMS
    if not p.is_file():
        if path:
            raise HspError(f"{p}: params file not found")
        return {}
    try:
        data = yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as e:
        raise HspError(f"{p}: invalid YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise HspError(f"{p}: expected a mapping at the top level")
    return data


def param(params: dict[str, Any], key: str, default: Any) -> Any:
    """Value at a dotted ``key`` (``record.fps``), or ``default`` when absent."""
    node: Any = params
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return default
        node = node[part]
    return node


def section(params: dict[str, Any], name: str, cls: type[C], ignore: tuple[str, ...] = ()) -> C:
    """A config dataclass from the ``name`` section (dotted: ``baselines.bc``); unknown keys
    are an error naming them."""
    return _build(param(params, name, None) or {}, name, cls, ignore)


def _build(values: dict[str, Any], where: str, cls: type[C], ignore: tuple[str, ...] = ()) -> C:
    """``cls`` from a mapping; a field whose default is itself a config dataclass (the
    tracker's ``rest`` and ``edges``) is built from its nested mapping the same way."""
    if not isinstance(values, dict):
        raise HspError(f"params.yaml: {where}: expected a mapping, got {values!r}")
    values = {k: v for k, v in values.items() if k not in ignore}
    known = {f.name: f for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise HspError(f"params.yaml: {where}: unknown keys {unknown} (known: {sorted(known)})")
    out = {}
    for k, v in values.items():
        if is_dataclass(known[k].default):
            out[k] = _build(v, f"{where}.{k}", type(known[k].default))
        else:
            out[k] = tuple(v) if isinstance(v, list) else v
    return cls(**out)
