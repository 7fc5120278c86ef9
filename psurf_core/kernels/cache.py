"""numba's on-disk cache with a key derived from every source a kernel can inline.

numba keys a cached kernel by its own bytecode and its file's time stamp; a function it
inlines from another file (a family's density composed into the MIS kernel, the shadow test
inlined into every walker) can change without the key changing, and the cache then serves
the old machine code. :class:`SourceKeyedCache` replaces that key by a digest of

* the function's qualified name and the values its closure captures (kernels composed per
  technique and MIS set are closures: numba's own key pickles them, which differs in every
  process, so they would never be found again), and
* the text of every project module the function's module, and any module of a captured
  function, imports, transitively (only modules of this project: installed packages are
  covered by numba's own version key).

Any change to a source that could be compiled into a kernel therefore recompiles it; nothing
else does. :func:`cached` attaches it to a dispatcher (numba's ``cache=True`` attaches
numba's ``FunctionCache``; this is the same class with another index key).
"""

from __future__ import annotations

import hashlib
import os
import sys
import types
from functools import cache

from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher

#: The project's root directory: modules whose file lies below it are hashed.
_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_PROJECT = os.path.join(_ROOT, "psurf_core")


def _project_file(module: types.ModuleType | None) -> str | None:
    """The source file of ``module`` when it belongs to ``psurf_core``, else None."""
    f = getattr(module, "__file__", None)
    if f and os.path.abspath(f).startswith(_PROJECT + os.sep) and f.endswith(".py"):
        return os.path.abspath(f)
    return None


def _module_of(value) -> types.ModuleType | None:
    """The module ``value`` (a module, function, class or numba dispatcher) comes from."""
    if isinstance(value, types.ModuleType):
        return value
    if isinstance(value, Dispatcher):
        value = value.py_func
    name = getattr(value, "__module__", None)
    return sys.modules.get(name) if isinstance(name, str) else None


@cache
def module_closure(name: str) -> tuple[str, ...]:
    """Sorted source files of project module ``name`` and every project module it
    references at module level (modules, functions, classes, dispatchers), transitively."""
    seen: set[str] = set()
    todo = [sys.modules.get(name)]
    while todo:
        mod = todo.pop()
        f = _project_file(mod)
        if f is None or f in seen:
            continue
        seen.add(f)
        for value in list(vars(mod).values()):
            dep = _module_of(value)
            if dep is not None and _project_file(dep) not in seen:
                todo.append(dep)
    return tuple(sorted(seen))


@cache
def _file_digest(path: str) -> str:
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def _cell_values(fn) -> list:
    return [c.cell_contents for c in (fn.__closure__ or ())]


def source_digest(fn) -> str:
    """Digest of everything compiled code of ``fn`` (a Python function) can depend on:
    its name and bytecode, its closure's values (recursively for captured functions and
    dispatchers) and the text of the project modules involved (:func:`module_closure`)."""
    h = hashlib.sha256()
    files: set[str] = set()
    seen: set[int] = set()

    def visit(f) -> None:
        if isinstance(f, Dispatcher):
            f = f.py_func
        if id(f) in seen:
            return
        seen.add(id(f))
        h.update(f"{f.__module__}.{f.__qualname__}".encode())
        h.update(f.__code__.co_code)
        files.update(module_closure(f.__module__))
        for v in _cell_values(f):
            if isinstance(v, Dispatcher | types.FunctionType):
                visit(v)
            else:
                mod = _module_of(v)
                if mod is not None and _project_file(mod):
                    files.update(module_closure(mod.__name__))
                h.update(repr(v).encode())

    visit(fn)
    for path in sorted(files):
        h.update(path.encode())
        h.update(_file_digest(path).encode())
    return h.hexdigest()


class SourceKeyedCache(FunctionCache):
    """numba's function cache, keyed by :func:`source_digest` (module docstring)."""

    def _index_key(self, sig, codegen):
        return (sig, codegen.magic_tuple(), source_digest(self._py_func))


def cached(dispatcher: Dispatcher) -> Dispatcher:
    """Give ``dispatcher`` (made with ``cache=False``) the on-disk cache keyed by its sources;
    a function numba cannot locate a cache for (defined in a string, a notebook cell) stays
    uncached."""
    try:
        dispatcher._cache = SourceKeyedCache(dispatcher.py_func)
    except RuntimeError:  # numba: "no locator available for file ..."
        pass
    return dispatcher
