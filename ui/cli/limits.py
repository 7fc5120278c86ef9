"""Before a command allocates or writes anything: its sizes against the memory limit, its
outputs against the disk.

The memory model is :mod:`psurf_core.budget`'s, checked by :mod:`psurf_core.budget_check`
against ``--memory-budget MIB`` where the command has it and it is given, otherwise against
the memory available on this machine; this module turns the refusals into
:class:`~ui.cli.common.CliError` (one line, exit code 2) and checks that every output folder
can be written (a file is created there and removed: catches read-only mounts, permissions
and a full disk) and has room for what the command will write.
"""

from __future__ import annotations

import os
import shutil
import tempfile

from .common import CliError
from .common import load_scene as _load_scene

__all__ = ["check_disk", "check_memory", "check_render_sizes", "load_scene_within",
           "probe_writable", "resolve_jobs"]


def load_scene_within(path: str, budget_mib: int | None, flag: str = "--memory-budget"):
    """The scene file ``path``, loaded only when its meshes fit while they load."""
    from psurf_core.budget_check import BudgetError, check_mesh_files

    try:
        check_mesh_files(path, budget_mib, flag=flag)
    except BudgetError as e:
        raise CliError(str(e)) from None
    return _load_scene(path)


def check_memory(need, budget_mib: int | None, **kw) -> None:
    """:func:`psurf_core.budget_check.check` as a :class:`CliError`."""
    from psurf_core.budget_check import BudgetError, check

    try:
        check(need, budget_mib, **kw)
    except BudgetError as e:
        raise CliError(str(e)) from None


def resolve_jobs(args, need_of) -> None:
    """``args.jobs`` ``"auto"`` replaced by its count (:func:`.parallel.auto_jobs`): the most
    worker processes, up to one a core, whose memory need ``need_of(n)`` (a
    :class:`~psurf_core.budget.Need`) fits ``--memory-budget`` or the memory available."""
    from psurf_core.budget_check import BudgetError, check

    from .parallel import auto_jobs

    if args.jobs != "auto":
        return

    def fits(n: int) -> bool:
        try:
            check(need_of(n), args.memory_budget)
        except BudgetError:
            return False
        return True

    args.jobs = auto_jobs(args, fits)


def probe_writable(flag: str, path: str, folder: str) -> None:
    """Create, write and remove a small file in ``folder`` (the folder of ``flag path``)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".psurf-probe-", dir=folder)
    except OSError as e:
        raise CliError(f"{flag} {path}: cannot write in {folder} ({_why(e)})") from None
    try:
        try:
            os.write(fd, b"psurf")
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as e:
        raise CliError(f"{flag} {path}: cannot write in {folder} ({_why(e)})") from None
    finally:
        try:
            os.remove(tmp)
        except OSError:
            pass


def check_disk(needs: list[tuple[str, str, str, int]]) -> None:
    """``needs``: ``(flag, path, folder, bytes)``; each folder must be writable, and each
    filesystem must have room for the bytes of all the outputs on it."""
    from psurf_core.budget import format_bytes

    by_device: dict[int, list] = {}
    for flag, path, folder, nbytes in needs:
        probe_writable(flag, path, folder)
        by_device.setdefault(os.stat(folder).st_dev, []).append((flag, path, folder, nbytes))
    for items in by_device.values():
        total = sum(n for *_, n in items)
        free = shutil.disk_usage(items[0][2]).free
        if total > free:
            flag, path, folder, _ = max(items, key=lambda t: t[3])
            what = " and ".join(f"{f} {p}" for f, p, *_ in items)
            raise CliError(f"{flag} {path}: {what} need about {format_bytes(total)} of disk, "
                           f"the filesystem of {folder} has {format_bytes(free)} free")


def check_render_sizes(args, scene, est, settings, ck_dir, ck):
    """Memory (the sizes against --memory-budget or the memory available) and disk (every
    output folder writable, room for the checkpoint and the outputs), before anything is
    allocated or written; returns the memory :class:`~psurf_core.budget.Need`."""
    from psurf_core import budget

    from .checkpoint import same_dir

    def need_of(jobs):
        return budget.render_need(scene, est, settings, jobs=jobs,
                                  local_workers=args.workers or 0, remote=args.dask is not None,
                                  checkpoint=ck_dir is not None)

    resolve_jobs(args, need_of)
    need = need_of(args.jobs)
    check_memory(need, args.memory_budget)
    folder = os.path.dirname(os.path.abspath(args.out))
    disk = [("--out", args.out, folder, budget.output_bytes(scene))]
    for flag, path, size in (("--png", args.png, 3), ("--exr", args.exr, 12)):
        if path is not None:
            px = scene.camera.width * scene.camera.height
            disk.append((flag, path, os.path.dirname(os.path.abspath(path)),
                         int(px * size * 1.01) + (64 << 10)))
    if ck_dir is not None:
        exists = os.path.isdir(ck_dir)
        flag = "--checkpoint" if args.checkpoint is not None else "--resume"
        # A new checkpoint is written beside the previous one, then replaces it.
        in_place = ck is not None and exists and same_dir(ck_dir, args.resume)
        size = budget.checkpoint_bytes(scene) * (1 if in_place else 2)
        disk.append((flag, ck_dir, ck_dir if exists else
                     os.path.dirname(os.path.abspath(ck_dir)), size))
    check_disk(disk)
    return need


def _why(e: OSError) -> str:
    return e.strerror or type(e).__name__
