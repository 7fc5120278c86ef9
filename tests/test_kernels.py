"""The compiled machinery's generic parts: the source-keyed cache, screen footprints, output
buffers, thread counts, Ctrl-C, and the warm-up before a time budget."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path

import numpy as np

from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings
from psurf_core.scene_io import load_scene

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted((ROOT / "scenes").glob("*.toml"))


def test_cache_key_follows_the_sources_a_kernel_inlines(tmp_path):
    """A kernel composed (as a closure) from a function of another module is found in the
    on-disk cache by a fresh process, and recompiled when that module's text changes: the
    cache never serves a kernel built from old sources (numba's own key misses both)."""
    pkg = tmp_path / "psurf_core"  # the digest covers modules below the project root only
    (pkg / "kernels").mkdir(parents=True)
    # A throwaway copy of the package layout the digest looks for, importing the real one.
    (pkg / "__init__.py").write_text("")
    (pkg / "kernels" / "__init__.py").write_text("")
    for name in ("cache.py", "jit.py", "numba_flags.py"):
        (pkg / "kernels" / name).write_text((ROOT / "psurf_core" / "kernels" / name).read_text())
    (pkg / "fam.py").write_text("from .kernels.jit import inline\n\n@inline\n"
                                "def density(x):\n    return x * 2.0\n")
    (pkg / "comp.py").write_text(textwrap.dedent("""\
        from .kernels.jit import kernel

        def make(f):
            @kernel
            def total(n):
                s = 0.0
                for i in range(n):
                    s += f(1.0)
                return s
            return total
        """))
    run = ("import sys; sys.path.insert(0, sys.argv[1]); from psurf_core.fam import density;"
           "from psurf_core.comp import make; k = make(density); v = k(3);"
           "print(v, sum(k.stats.cache_hits.values()))")

    def once():
        out = subprocess.run([sys.executable, "-c", run, str(tmp_path)], capture_output=True,
                             text=True, check=True, env={"NUMBA_CACHE_DIR": str(tmp_path / "c"),
                                                        "PATH": "/usr/bin:/bin"})
        value, hits = out.stdout.split()
        return float(value), int(hits)

    assert once() == (6.0, 0)  # compiled
    assert once() == (6.0, 1)  # found in the cache by a new process
    (pkg / "fam.py").write_text((pkg / "fam.py").read_text().replace("2.0", "3.0"))
    assert once() == (9.0, 0)  # the inlined source changed: recompiled, not the old code
    assert once() == (9.0, 1)


def test_compiled_screen_rects_equal_binning():
    """The compiled pixel rectangles equal ``binning.screen_rects`` on finite boxes (what
    clipped primitive bounds are), including empty boxes and boxes reaching behind the
    camera."""
    from psurf_core.binning import screen_rects
    from psurf_core.kernels.spans import _screen_rects, camera_row

    for path in SCENES:
        cam = load_scene(path).camera
        rng = np.random.default_rng(5)
        lo = cam.position + rng.uniform(-8, 8, (500, 3))
        hi = lo + rng.uniform(-0.5, 4, (500, 3))
        want = screen_rects(cam, lo, hi)
        got = _screen_rects(lo, hi, camera_row(cam))
        assert np.any(want[1] > want[0]) and np.any(want[1] == want[0])
        for w, g in zip(want, got, strict=True):
            np.testing.assert_array_equal(g, w)


def test_spans_before_counts_each_spans_rays_and_chunk_slots():
    """``fused.spans_before``: the running sums of each span's candidate pairs (the rays of
    its pixels, ``cs[row * width + c1] - cs[row * width + c0]``) and of binning's chunk
    sizes ``(c1 - c0) * per_pix``, from 0; and the chunk boundaries taken from those sums are
    binning's own (``_chunk_bounds`` of the sizes)."""
    from psurf_core.binning import _chunk_bounds, chunk_bounds_cum
    from psurf_core.kernels.fused import spans_before

    rng = np.random.default_rng(3)
    width, height, per_pix = 17, 11, 3
    cs = np.concatenate([[0], np.cumsum(rng.integers(0, per_pix + 1, width * height))])
    n = 400
    row = rng.integers(0, height, n)
    c0 = rng.integers(0, width, n)
    c1 = np.minimum(c0 + rng.integers(0, 6, n), width)
    before, slots = spans_before(cs, row, c0, c1, width, per_pix)
    cand = cs[row * width + c1] - cs[row * width + c0]
    np.testing.assert_array_equal(before, np.concatenate([[0], np.cumsum(cand)]))
    sizes = (c1 - c0) * per_pix
    np.testing.assert_array_equal(slots, np.concatenate([[0], np.cumsum(sizes)]))
    assert cand.min() == 0 and cand.max() > 5  # empty and full spans both drawn
    for budget in (1, 7, 50, 10**9):
        assert chunk_bounds_cum(slots[1:], budget) == _chunk_bounds(sizes, budget)


def test_ctrl_c_inside_a_kernel_stays_a_keyboard_interrupt():
    """A SIGINT handled while numba boxes a result arrives as a chain of SystemErrors caused
    by the KeyboardInterrupt (seen with ``render --checkpoint``); the compiled paths turn it
    back into the KeyboardInterrupt, other SystemErrors pass through."""
    from psurf_core.kernels.jit import ctrl_c_kept, interrupted

    def chain(root):
        try:
            try:
                try:
                    raise root
                except BaseException as e:
                    raise SystemError("returned a result with an exception set") from e
            except SystemError as e:
                raise SystemError("returned a result with an exception set") from e
        except SystemError as e:
            return e

    assert interrupted(chain(KeyboardInterrupt()))
    assert not interrupted(chain(ValueError("x")))
    assert not interrupted(SystemError("plain"))
    try:
        with ctrl_c_kept():
            raise chain(KeyboardInterrupt())
    except KeyboardInterrupt:
        pass


def test_output_buffers_are_reused_only_when_released():
    """Hits of a chunk that something still references (even through a view of a view) are
    never overwritten; released ones are reused."""
    from psurf_core.kernels.buffers import HitBuffers

    fields = ((np.int64, 1), (np.float64, 3), (np.int8, 3))
    pool = HitBuffers()
    first = pool.take("k", fields, 100)
    first[0][:] = 7
    kept = first[0][10:20][::2]  # a view of a view keeps the lease alive
    del first
    second = pool.take("k", fields, 100)  # slot 0 is leased: slot 1
    third = pool.take("k", fields, 100)  # both leased: fresh memory
    for out in (second, third):
        out[0][:] = -1
    np.testing.assert_array_equal(kept, 7)
    s1 = pool.storage["k"][1].__array_interface__["data"][0]
    assert second[0].__array_interface__["data"][0] == s1
    del second, third
    fourth = pool.take("k", fields, 50)  # slot 0 still leased (kept), slot 1 released
    assert fourth[0].__array_interface__["data"][0] == s1
    np.testing.assert_array_equal(kept, 7)
    assert [a.shape for a in fourth] == [(50,), (50, 3), (50, 3)]
    assert all(a.__array_interface__["data"][0] % 8 == 0 for a in fourth)


def test_threads_only_on_cores_other_processes_leave_free(monkeypatch):
    """numba's thread count, lowered to the cores the rest of the machine leaves idle."""
    from psurf_core.kernels import threads

    monkeypatch.setattr(threads, "get_num_threads", lambda: 2)
    monkeypatch.setattr(threads, "_CPUS", 2)
    for others, want in [(0.0, 2), (0.4, 2), (0.7, 1), (1.0, 1), (3.0, 1)]:
        monkeypatch.setattr(threads, "_OTHER_LOAD", lambda o=others: o)
        assert threads.thread_count() == want
    monkeypatch.setattr(threads, "get_num_threads", lambda: 1)
    monkeypatch.setattr(threads, "_OTHER_LOAD", lambda: 0.0)
    assert threads.thread_count() == 1
    load = threads._OtherLoad()
    monkeypatch.setattr(threads, "_LOAD_REFRESH", 0.0)
    assert load() >= 0.0 and load() >= 0.0


def test_pieces_handed_out_from_a_helper_thread_run_there():
    """A piece that hands out pieces itself (one helper thread: the pool's only one is busy
    with it) runs them on its own thread instead of waiting for ever; every piece runs once,
    and in_pieces covers its range exactly."""
    import threading

    from psurf_core.kernels import threads

    seen, lock = [], threading.Lock()

    def inner(j):
        with lock:
            seen.append(("inner", j, threading.current_thread().name))

    def outer(j):
        threads.on_threads(inner, 3, 2)
        with lock:
            seen.append(("outer", j, threading.current_thread().name))

    done = threading.Event()
    t = threading.Thread(target=lambda: (threads.on_threads(outer, 4, 2), done.set()),
                         daemon=True)
    t.start()
    assert done.wait(60), "nested on_threads did not finish"
    assert sorted(j for k, j, _ in seen if k == "outer") == [0, 1, 2, 3]
    assert len([1 for k, _, _ in seen if k == "inner"]) == 12
    covered = []
    threads.in_pieces(lambda a, b: covered.extend(range(a, b)), 1001, 2, min_size=10)
    assert sorted(covered) == list(range(1001))
    small = []
    threads.in_pieces(lambda a, b: small.append((a, b)), 15, 2, min_size=10)
    assert small == [(0, 15)]


def test_guided_cuts_cover_the_range_large_pieces_first():
    """``guided_cut`` covers ``0 .. n - 1`` in consecutive non-empty ranges, each at most
    the one before it (the last ``GUIDED_RATIO ** (k - 1)`` of the first, to a range's
    rounding), ``k`` of them where ``n`` is large (an empty range is dropped); the walker's
    fixed chunk cut (``fused.CHUNK_CUT``) runs from 0 to 1 with shrinking pieces."""
    from psurf_core.kernels import fused, threads

    for n, k in ((1001, 8), (100_000, 12), (5, 8), (8, 8), (1, 3)):
        cut = threads.guided_cut(n, k)
        size = np.diff(cut)
        assert cut[0] == 0 and cut[-1] == n and (size > 0).all(), (n, k)
        assert len(size) <= k, (n, k)
        if n >= 100 * k:
            assert len(size) == k, (n, k)
            assert (size[1:] <= size[:-1] + 1).all(), (n, k)
            want = threads.GUIDED_RATIO ** (k - 1)
            assert abs(size[-1] / size[0] - want) < 0.01, (n, k)
    f = fused.CHUNK_CUT
    assert f[0] == 0.0 and f[-1] == 1.0 and len(f) == fused.CHUNK_PIECES + 1
    assert (np.diff(np.diff(f)) < 0).all()


def test_a_time_budget_warms_the_kernels_up_first_without_changing_the_image(monkeypatch):
    """``render(time_budget=...)`` compiles/loads the kernels before its clock starts (a cold
    numba compile took the whole 1 s budget of an equal-time comparison on CI), through a
    throw-away pass that changes nothing in the image; ``passes=`` renders skip it."""
    import psurf_core.render as rmod

    scene = load_scene(SCENES[[p.stem for p in SCENES].index("area_occluder")])
    scene = replace(scene, camera=replace(scene.camera, width=24, height=16))
    est = parse_estimator("planes", scene)
    settings = RenderSettings(photons=200)
    warmed_passes = []
    real_pass = rmod.render_pass

    def counting_pass(sc, *a, **k):
        warmed_passes.append((sc.camera.width, sc.camera.height))
        return real_pass(sc, *a, **k)

    monkeypatch.setattr(rmod, "_WARMED", set())
    monkeypatch.setattr(rmod, "render_pass", counting_pass)
    plain = rmod.render(scene, est, settings, passes=1, seed=4)
    assert warmed_passes == [(24, 16)] and rmod._WARMED == set()
    timed = rmod.render(scene, est, settings, time_budget=1e-9, seed=4)
    assert warmed_passes[1:] == [rmod._WARM_SIZE, (24, 16)]
    assert rmod._WARMED == {"planes"}
    assert timed.passes == 1 and np.array_equal(timed.mean, plain.mean)
    rmod.render(scene, est, settings, time_budget=1e-9, seed=4)  # warmed once per process
    assert warmed_passes[3:] == [(24, 16)]
    reference = parse_estimator("reference", scene)
    rmod.warm_up(scene, reference, settings)
    assert len(warmed_passes) == 4
