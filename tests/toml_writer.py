"""A tiny TOML writer for tests that build scene files from dicts (``test_scene.py``, the
bad-input corpus): top-level scalars, ``[tables]`` and ``[[arrays of tables]]``, and values
TOML itself cannot hold in a scene (``nan``, ``inf``) written as TOML spells them."""

from __future__ import annotations

import json
import math


def toml_value(v) -> str:
    """One value (bool, int, float, str, list or inline table) as TOML text."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(v)


def _is_aot(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(doc: dict) -> str:
    """``doc`` as TOML: top-level scalars, then [tables] and [[arrays of tables]]."""
    lines = [f"{k} = {toml_value(v)}" for k, v in doc.items()
             if not (isinstance(v, dict) or _is_aot(v))]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += ["", f"[{k}]"] + [f"{kk} = {toml_value(vv)}" for kk, vv in v.items()]
        elif _is_aot(v):
            for item in v:
                lines += ["", f"[[{k}]]"] + [f"{kk} = {toml_value(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"
