"""Declared records: one ``NamedTuple`` class names the fields of a row, in numpy and in
compiled code alike.

A family declares its primitive geometry and its hits as ``NamedTuple`` classes whose fields
are floats or 3-vectors (:data:`Vec`). In numpy they are structured arrays of
:func:`dtype_of` the class, viewed as ``numpy.recarray`` so that ``G.x1`` is the (N, 3) column
(:func:`table`). In compiled code a row is the ``NamedTuple`` itself, with 3-tuples for
vectors: :func:`load` reads row ``p`` of a table and :func:`store` writes one, from the
table's (N, F) float view (:func:`flat`). So a kernel reads ``G.beta``, never a numbered column,
and a schema lives in one place per family.

Every field is float64 (flags are 0.0 / 1.0): the flat view of a table is then a plain
(N, F) float array, which is what the compiled code indexes.

:func:`replace` is ``NamedTuple._replace`` for one field, in compiled code too (numba has no
``_replace``).
"""

from __future__ import annotations

import functools
import typing

import numpy as np
from numba import types
from numba.core.extending import overload

#: Annotation of a 3-vector field (an (N, 3) column in numpy, a 3-tuple in compiled code).
Vec = tuple[float, float, float]


@functools.cache
def widths(cls) -> tuple[int, ...]:
    """Float columns of each field of the record class ``cls`` (3 for :data:`Vec`, else 1)."""
    hints = typing.get_type_hints(cls)  # resolves string annotations (``from __future__``)
    return tuple(len(typing.get_args(hints[n])) if typing.get_origin(hints[n]) is tuple else 1
                 for n in cls._fields)


@functools.cache
def dtype_of(cls) -> np.dtype:
    """The structured dtype of the record class ``cls`` (float64 fields, vectors as (3,))."""
    return np.dtype([(n, "f8", w) if w > 1 else (n, "f8")
                     for n, w in zip(cls._fields, widths(cls), strict=True)])


def table(cls, n: int | None = None, **columns) -> np.recarray:
    """A record table of class ``cls``: ``columns`` (one (N,) or (N, 3) array per field; all
    fields must be given) or, with ``n``, ``n`` zero rows."""
    if columns:
        missing = set(cls._fields) - set(columns)
        if missing:
            raise ValueError(f"{cls.__name__}: missing fields {sorted(missing)}")
        n = len(next(iter(columns.values())))
    out = np.zeros(int(n or 0), dtype_of(cls)).view(np.recarray)
    for name, col in columns.items():
        out[name] = col
    return out


def flat(t: np.ndarray) -> np.ndarray:
    """(N, F) float64 view of a record table (what compiled code indexes); F is the number of
    float columns of the record."""
    a = np.ascontiguousarray(t).view(np.ndarray)
    return a.view(np.float64).reshape(a.shape[0], a.dtype.itemsize // 8)


def load(rows, p, cls):
    """Row ``p`` of the flat table ``rows`` as a ``cls`` instance (vectors as tuples)."""
    cols, out = 0, []
    for w in widths(cls):
        out.append(tuple(float(x) for x in rows[p, cols:cols + w]) if w > 1
                   else float(rows[p, cols]))
        cols += w
    return cls(*out)


def store(rows, n, rec) -> None:
    """Write the record ``rec`` into row ``n`` of the flat table ``rows``."""
    rows[n] = np.concatenate([np.ravel(np.asarray(v, dtype=float)) for v in rec])


def replace(rec, name, value):
    """``rec`` with field ``name`` set to ``value`` (``NamedTuple._replace`` of one field)."""
    return rec._replace(**{name: value})


# ------------------------------------------------------------------------- compiled twins
# Each is generated from the record's type when a kernel is compiled (numba ``overload``):
# the loops over fields above unrolled into straight-line code.
def _compile(src: str, name: str, namespace: dict):
    exec(src, namespace)  # noqa: S102 - generated from a record's field list only
    return namespace[name]


@overload(load, inline="always", prefer_literal=True)
def _load(rows, p, cls):
    nt = cls.instance_class
    parts, col = [], 0
    for w in widths(nt):
        items = ", ".join(f"rows[p, {col + k}]" for k in range(w))
        parts.append(f"({items})" if w > 1 else items)
        col += w
    return _compile(f"def impl(rows, p, cls):\n    return NT({', '.join(parts)})\n", "impl",
                    {"NT": nt})


@overload(store, inline="always")
def _store(rows, n, rec):
    if not isinstance(rec, types.BaseNamedTuple):
        return None
    lines, col = [], 0
    for i, t in enumerate(rec.types):
        for k in range(t.count if isinstance(t, types.UniTuple) else 1):
            item = f"rec[{i}][{k}]" if isinstance(t, types.UniTuple) else f"rec[{i}]"
            lines.append(f"    rows[n, {col}] = {item}")
            col += 1
    return _compile("def impl(rows, n, rec):\n" + "\n".join(lines) + "\n", "impl", {})


@overload(replace, inline="always", prefer_literal=True)
def _replace(rec, name, value):
    if not isinstance(name, types.StringLiteral):
        return None
    i = rec.fields.index(name.literal_value)
    args = ", ".join("value" if j == i else f"rec[{j}]" for j in range(len(rec.fields)))
    return _compile(f"def impl(rec, name, value):\n    return NT({args})\n", "impl",
                    {"NT": rec.instance_class})
