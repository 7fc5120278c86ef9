"""Long runs stay flat: memory kept for reuse is resident only as far as the pass in hand needs.

:func:`psurf_core.memory_release.release_pages` hands back the pages of a buffer past a
need, and :class:`psurf_core.kernels.buffers.HitBuffers` calls it on every lease, so a rare
large pass (a trace's outputs span the deepest photon of its batch) does not leave its pages
resident for the rest of the run. Residency is read from ``/proc/self/pagemap`` (its
"present" bit, readable without privileges), so these tests run on Linux only.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from psurf_core.kernels.buffers import RECENT_TAKES, HitBuffers
from psurf_core.memory_release import release_free_memory, release_pages

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or not os.path.exists("/proc/self/pagemap"),
    reason="page residency is read from Linux's /proc/self/pagemap")

PAGE = os.sysconf("SC_PAGE_SIZE")


def resident(buf: np.ndarray) -> np.ndarray:
    """(pages,) bool: which pages spanned by ``buf``'s memory are resident."""
    first = buf.ctypes.data // PAGE
    last = (buf.ctypes.data + buf.nbytes - 1) // PAGE
    with open("/proc/self/pagemap", "rb") as f:
        f.seek(first * 8)
        entries = np.frombuffer(f.read((last - first + 1) * 8), dtype=np.uint64)
    return (entries >> np.uint64(63)).astype(bool)


def page_aligned(pages: int) -> np.ndarray:
    """A uint8 array of ``pages`` whole pages starting on a page boundary (cut from a larger
    allocation, so the pages around it belong to the same array)."""
    raw = np.empty((pages + 2) * PAGE, np.uint8)
    skip = -raw.ctypes.data % PAGE
    return raw[skip:skip + pages * PAGE]


def test_release_pages_hands_back_whole_pages_past_keep_only():
    buf = page_aligned(64)
    buf[:] = 7
    assert resident(buf).all()
    keep = 10 * PAGE + 100  # page 10 holds kept bytes: it stays
    assert release_pages(buf, keep)
    res = resident(buf)
    assert res[:11].all() and not res[11:].any(), np.flatnonzero(res)
    assert (buf[:keep] == 7).all()  # the kept bytes are untouched
    assert (buf[11 * PAGE:] == 0).all()  # released pages read as zeros (and come back)
    assert resident(buf).all()


def test_release_pages_never_touches_a_neighbours_page():
    """A buffer that starts and ends inside pages: those partial pages are kept."""
    raw = page_aligned(8)
    raw[:] = 1
    buf = raw[100:7 * PAGE + 5]
    release_pages(buf, 0)
    res = resident(raw)
    assert res[0] and res[7] and not res[1:7].any()
    assert (raw[:PAGE] == 1).all() and (raw[7 * PAGE:] == 1).all()


def test_hit_buffers_hand_back_a_rare_large_need_once_it_is_old():
    """A large lease, written, then small ones from the same storage: while the large need is
    among the last RECENT_TAKES its pages stay (alternating needs must not re-fault), after
    that the storage's pages past the small need are no longer resident (before, they stayed
    until the run ended, and each rarer, larger pass raised that mark)."""
    pool = HitBuffers()
    fields = ((np.float64, 3),)
    big = pool.take("k", fields, 200_000)  # 4.8 MB
    big[0][:] = 1.0
    storage = pool.storage["k"][0]
    assert resident(storage).sum() * PAGE >= 4_800_000
    del big
    for k in range(RECENT_TAKES - 1):
        small = pool.take("k", fields, 1000)  # 24 kB, the same storage
        assert pool.storage["k"][0] is storage
        assert small[0].__array_interface__["data"][0] == storage.ctypes.data
        small[0][:] = 2.0
        del small
        assert resident(storage).sum() * PAGE >= 4_800_000, k  # still recent: kept
    small = pool.take("k", fields, 1000)  # the large need has left the window
    # the need's pages, one more where the storage starts mid-page, and the storage's last,
    # partial page (it may share a page with another allocation: never released)
    assert resident(storage).sum() * PAGE <= 24_000 + 3 * PAGE
    small[0][:] = 2.0
    del small
    again = pool.take("k", fields, 200_000)  # the large need again: its pages come back
    again[0][:] = 3.0
    assert (again[0] == 3.0).all()


def test_release_free_memory_runs():
    assert release_free_memory() in (True, False)


#: A child that allocates a pass's worth of few-MiB arrays, touches and frees them, twice,
#: and prints the page faults of the second round. ``argv[1]``: ``none`` (glibc's defaults),
#: ``call`` (``keep_freed_memory`` alone) or ``import`` (``import psurf_core``).
_ROUNDS = r"""
import resource, sys
import numpy as np
if sys.argv[1] == "call":
    from psurf_core.memory_release import keep_freed_memory
    assert keep_freed_memory()
elif sys.argv[1] == "import":
    import psurf_core
def one_round():
    arrays = [np.ones(3 << 17) for _ in range(12)]  # 12 x 3 MiB, touched
    del arrays
one_round()
f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
one_round()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
"""


def _second_round_faults(how: str) -> int:
    # A child: this process imported psurf_core, which calls keep_freed_memory, and the
    # control must start from glibc's defaults.
    env = {**os.environ, "PYTHONPATH": os.path.dirname(os.path.dirname(__file__))}
    out = subprocess.run([sys.executable, "-c", _ROUNDS, how], env=env,
                         capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


def test_keep_freed_memory_reuses_a_pass_worth_of_arrays_without_page_faults():
    """With glibc's defaults each 3 MiB array is mapped and unmapped again (a page fault for
    every page it touches, every pass: 12 x 768 pages); kept, the second round reuses the
    first's heap."""
    pages = 12 * (3 << 20) // PAGE
    assert _second_round_faults("none") > 0.8 * pages  # the control: faults every page
    assert _second_round_faults("call") < 0.05 * pages
    assert _second_round_faults("import") < 0.05 * pages  # psurf_core calls it on import


def test_trim_now_and_then_trims_once_a_period(monkeypatch):
    from psurf_core import memory_release as mr

    calls = []
    monkeypatch.setattr(mr, "release_free_memory", lambda: calls.append(1) or True)
    monkeypatch.setattr(mr, "_LAST_TRIM", [0.0])
    assert mr.trim_now_and_then(seconds=1e-9)  # long past: trims
    assert not mr.trim_now_and_then(seconds=3600.0)  # just trimmed: not again
    assert calls == [1]


def test_every_render_pass_lets_long_runs_trim(monkeypatch):
    """The window and the web sessions render passes in loops of their own: the period's trim
    must come from ``render_pass`` itself."""
    from psurf_core import render
    from psurf_core.estimators import parse_estimator
    from psurf_core.scene_io import load_scene

    seen = []
    monkeypatch.setattr(render, "trim_now_and_then", lambda: seen.append(1))
    root = os.path.dirname(os.path.dirname(__file__))
    scene = load_scene(os.path.join(root, "scenes", "area.toml"))
    render.render_pass(scene, parse_estimator("beams", scene), 0, 0,
                       render.RenderSettings(photons=20))
    assert seen == [1]
