"""A run's memory need against the limit: refuse it before allocating, saying what to change.

The limit (:func:`limit`) is ``--memory-budget MIB`` where a command has the flag and it is
given, otherwise the memory this machine has available now (:func:`available_memory`:
``MemAvailable``, or what a container's cgroup leaves). :func:`check` raises
:class:`BudgetError` with one line: the need (:class:`psurf_core.budget.Need`), its largest
parts, the limit, and the largest value of the size behind the largest part that would fit.
:func:`check_mesh_files` does the same for the meshes a scene file names, before trimesh
loads them. :func:`photon_limit` is the largest photon count per pass that fits the window's
progressive render (its photon slider's bound). Memory handed back to the system during long
runs: :mod:`psurf_core.memory_release`.
"""

from __future__ import annotations

import math
import os

from .budget import MIB, TRIANGLE_LOAD_BYTES, Need, format_bytes, progressive_need

__all__ = ["BudgetError", "available_memory", "check", "check_mesh_files", "limit",
           "photon_limit"]


class BudgetError(ValueError):
    """A run that does not fit: the message is one line (what it needs, what to change)."""


def available_memory() -> int | None:
    """Bytes this process may still allocate: the smaller of the machine's ``MemAvailable``
    and what its cgroup (a container's limit) leaves; ``None`` when neither is known."""
    found = []
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
                    break
    except (OSError, ValueError):
        pass
    try:
        with open("/sys/fs/cgroup/memory.max") as f:
            cap = f.read().strip()
        if cap != "max":
            with open("/sys/fs/cgroup/memory.current") as f:
                found.append(max(0, int(cap) - int(f.read().strip())))
    except (OSError, ValueError):
        pass
    if not found:
        try:
            found.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            return None
    return int(min(found))


def limit(budget_mib: int | None, flag: str = "--memory-budget") -> tuple[float | None, str]:
    """``(bytes, phrase)`` of the limit a run is checked against: ``flag``'s value when given,
    else the memory available now (``None`` bytes: unknown, nothing is checked)."""
    if budget_mib is not None:
        return float(budget_mib) * MIB, f"{flag} {budget_mib} MiB"
    avail = available_memory()
    if avail is None:
        return None, "the available memory (unknown)"
    return float(avail), f"the {format_bytes(avail)} of memory available on this machine"


def check(need: Need, budget_mib: int | None, *, what: str = "the render",
          flag: str = "--memory-budget", photons_flag: str = "--photons",
          spp_flag: str = "--spp") -> None:
    """Raise :class:`BudgetError` when ``need`` exceeds the limit (:func:`limit`), or, with a
    budget given, the memory available on this machine.

    The message names the total and its largest parts, the limit, and what to change: the
    largest size that would fit with everything else kept, and the budget that would hold
    the run (when the machine has that much).
    """
    cap, phrase = limit(budget_mib, flag)
    total = need.total
    if cap is not None and total > cap:
        avail = available_memory() if budget_mib is not None else None
        raise_it = f", or raise {flag} to {math.ceil(total / MIB)} MiB" \
            if budget_mib is not None and (avail is None or total <= avail) else ""
    else:
        avail = available_memory() if budget_mib is not None else None
        if avail is None or total <= avail:
            return
        cap, raise_it = float(avail), ""
        phrase = f"the {format_bytes(avail)} of memory available on this machine"
    parts = list(need.parts().items())
    shown = ", ".join(f"{k} {format_bytes(v)}" for k, v in parts[:3])
    advice = _advice(need, cap, parts[0][0], photons_flag, spp_flag)
    raise BudgetError(f"{what} would need about {format_bytes(total)} of memory ({shown}), "
                      f"more than {phrase}; {advice}{raise_it}")


def _advice(need: Need, cap: float, largest: str, photons_flag: str, spp_flag: str) -> str:
    """What to change: the size behind the largest part, and how far."""
    spp_room = (cap - need.without("spp")) // (need.pixels * need.per_ray) if need.per_ray else 0
    if "image" in largest or ("camera rays" in largest and (need.spp == 1 or spp_room < 1)):
        per = need.per_pixel + need.spp * need.per_ray
        n = int((cap - need.without("pixels")) // per) if per else 0
        if n < 1:
            return "no resolution fits beside the rest of the run; lower the other sizes"
        w, h = _fit_side(need.width, need.height, n)
        return (f"lower camera.resolution in the scene file (at most ~{n:,} pixels fit, "
                f"e.g. {w}x{h})")
    if "camera rays" in largest:
        return f"lower {spp_flag} to at most {int(spp_room)} (or the resolution)"
    if "photons" in largest:
        n = need.max_photons(cap)
        if n >= 1:
            return f"lower {photons_flag} to at most {n:,}"
        return f"lower {photons_flag} (not even one photon fits beside the rest of the run)"
    if "triangles" in largest:
        n = int((cap - need.without("triangles")) // need.per_triangle)
        return f"use meshes with fewer triangles (at most ~{max(n, 0):,} fit)"
    if "worker" in largest:
        return "use fewer worker processes (--jobs/--workers)"
    if "picture" in largest:
        return "lower --size"
    return "lower the sizes above"


def _fit_side(w: int, h: int, pixels: int) -> tuple[int, int]:
    """The largest ``W x H`` with the aspect of ``w x h`` within ``pixels``."""
    s = math.sqrt(pixels / (w * h))
    return max(1, int(w * s)), max(1, int(h * s))


def photon_limit(scene, estimators, settings, *, budget_mib: int | None = None,
                 workers: int = 1, breakdown: bool = False, inspect: bool = True) -> int:
    """The largest photon count per pass that fits the window's progressive render.

    For the window's photon slider: clamp its value to this (0 when not even the rest of the
    run fits; ``2**62`` when any count fits). ``estimators`` are the parsed estimators
    shown, ``settings`` the window's :class:`~psurf_core.render.RenderSettings` (its
    ``photons`` is ignored), ``workers`` its background processes; ``inspect`` counts the
    stages' record of one whole pass, which keeps every photon. Without ``budget_mib`` the
    limit is the memory available now (:func:`available_memory`; unknown: ``2**62``).
    """
    cap, _ = limit(budget_mib)
    if cap is None:
        return 1 << 62
    need = progressive_need(scene, estimators, settings, workers=workers, breakdown=breakdown,
                            inspect=inspect)
    return need.max_photons(cap)


def check_mesh_files(scene_path, budget_mib: int | None, *,
                     flag: str = "--memory-budget") -> None:
    """Raise :class:`BudgetError` before loading when the scene file's meshes would not fit
    while trimesh loads them (:data:`TRIANGLE_LOAD_BYTES` per triangle; counts from
    :func:`psurf_core.mesh_files.triangle_count`). Meshes of unknown size pass: they are
    counted once loaded."""
    from .mesh_files import scene_mesh_files, triangle_count

    cap, phrase = limit(budget_mib, flag)
    if cap is None:
        return
    meshes = []
    for key, path in scene_mesh_files(scene_path):
        # A file this small cannot hold more triangles than fit (>= 8 bytes per face
        # record): skip the count.
        try:
            small = os.path.getsize(path) * TRIANGLE_LOAD_BYTES / 8 <= cap
        except OSError:
            continue  # the loader names the missing file
        n = None if small else triangle_count(path)
        if n:
            meshes.append((key, path, n))
    total = sum(n for _, _, n in meshes) * TRIANGLE_LOAD_BYTES
    if total <= cap:
        return
    key, path, n = max(meshes, key=lambda m: m[2])
    fit = int((cap - (total - n * TRIANGLE_LOAD_BYTES)) // TRIANGLE_LOAD_BYTES)
    more = f", or raise {flag} to {math.ceil(total / MIB)} MiB" if budget_mib is not None else ""
    raise BudgetError(f"{scene_path}: {key}: {path} has {n:,} triangles; loading the scene's "
                      f"meshes would need about {format_bytes(total)} of memory, more than "
                      f"{phrase}; use a mesh with at most ~{max(fit, 0):,} triangles{more}")
