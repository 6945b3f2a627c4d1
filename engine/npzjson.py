"""JSON values inside numpy archives (a leaf: imports nothing of Lanterna).

What it computes
    ``pack_json(obj)``  dicts, lists, numbers, strings and numpy values as a 0-d unicode
        array, so that an ``.npz`` archive read with ``allow_pickle=False`` can carry them
        (the maps' statistics, the settings and report of a bake: ``engine/artifacts.py``).
    ``unpack_json(value)``  the inverse.
    ``jsonable(obj)``  the plain JSON value ``pack_json`` writes: dicts with non-string keys
        (the shadow map's per-light stats, keyed by light index) become
        ``{"__items__": [[key, value], ...]}`` so that their keys come back as they were
        (lists as tuples); numpy arrays and scalars become lists and numbers; anything else
        its ``str``.
"""
from __future__ import annotations

import json

import numpy as np

__all__ = ["pack_json", "unpack_json", "jsonable"]


def jsonable(obj):
    """Plain JSON values; dicts with non-string keys (the shadow map's per-light stats keyed by
    light index) become {"__items__": [[key, value], ...]} so their int keys come back."""
    if isinstance(obj, dict):
        if all(isinstance(k, str) for k in obj):
            return {k: jsonable(v) for k, v in obj.items()}
        return {"__items__": [[jsonable(k), jsonable(v)] for k, v in obj.items()]}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if obj is None or isinstance(obj, (str, bool, int, float)):
        return obj
    return str(obj)


def _restore(obj):
    if isinstance(obj, dict):
        if set(obj) == {"__items__"}:
            return {_key(k): _restore(v) for k, v in obj["__items__"]}
        return {k: _restore(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_restore(v) for v in obj]
    return obj


def _key(k):
    return tuple(k) if isinstance(k, list) else k


def pack_json(obj) -> np.ndarray:
    """``obj`` (dicts, lists, numbers, strings, numpy values) as a 0-d unicode array."""
    return np.array(json.dumps(jsonable(obj), allow_nan=True))


def unpack_json(value):
    """The inverse of ``pack_json``."""
    return _restore(json.loads(str(np.asarray(value))))
