"""Where one compiled pass goes: screen spans against the walker, the walker's shadow tests and
contribution, and the walk on one thread against two.

One batch of photons (pass 0 of seed 0, as :func:`benchmarks.stages.stage_pass` draws it) is
traced and its primitives are created once; every round then runs the same compiled pass
(:func:`psurf_core.kernels.fused.fused_pass`, the path ``render_pass`` takes, without emitted
hits) over them, so every round and every variant does the same work. Per technique of the
spec (an MIS set's members each in their set; a member's ``@share`` is ignored: every member
sweeps every photon, as in ``stages.py``), it prints:

* default: per pass, the wall and CPU ms (``time.process_time``: every thread of this
  process) of the whole pass, of its screen spans (``fused._Run.spans``: the hulls clipped and
  projected) and of its walker (``fused._Run.walk_chunk``: the compiled walk over every chunk,
  buffers included; "other" is the rest: ray table, per-span candidate counts, chunking, the
  adding of the compact rows to the image), the hits, the candidate ray-primitive pairs,
  hits per wall second and the most threads a chunk ran on;
* ``--ablate``: CPU ms per pass of the walker as it is (``base``) and rebuilt
  (``dataclasses.replace`` on the technique's compiled family record) without its shadow
  statuses (``novis``: every segment clear), without its contribution (``nocontrib``: the
  ray distance ``s`` instead) or without both (``neither``), run in alternating rounds in one
  process (the order rotated each round), so that load drift hits every variant alike. The
  hits are the same in every variant (ablation changes only the work per hit; it is checked).
  Without the statuses, a hit they would have blocked is shaded (and MIS-weighted) like any
  other, so ``novis`` understates the saving where many hits are blocked. Per technique of
  the spec it also prints the walker's CPU ns a hit and the shares of its shadow statuses and
  contribution (each technique's own walk in its set);
* ``--scaling``: the walker's wall ms on 1 and on 2 numba threads (alternating rounds) and
  their ratio. A chunk goes to threads only from ``fused.THREADED_MIN_PAIRS`` candidate
  pairs, and ``threads.thread_count`` uses no more threads than other processes leave cores
  free: the "threads" column says what was used (``--no-load-cap`` lifts that cap).

Figures are medians over the rounds after the first (which loads the kernels, compiles the
ablated walkers and touches cold buffers). numba runs on ``--threads`` threads (default 1:
the CPU time is then the pass's own).

Usage::

    python benchmarks/pass_breakdown.py SCENE.toml [--spec planes] [--photons 5000]
        [--rounds 6] [--threads 1] [--ablate] [--scaling] [--no-load-cap] [--json PATH]
        [--scatter KMIN KMAX] [--resolution W,H]
    python benchmarks/pass_breakdown.py scenes/area.toml --ablate
    python benchmarks/pass_breakdown.py scenes/study_medium.toml --scatter 2 3 \
        --resolution 256,192 --spec "mis:planes+plane-ut-short+cone-short" --photons 900 --ablate
    python benchmarks/pass_breakdown.py scenes/point.toml --scaling

Not a test: the times move with the machine's load; compare figures of one run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import sys
from contextlib import ExitStack, contextmanager

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numba  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks.stages import Clock  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.kernels import fused  # noqa: E402
from psurf_core.kernels.jit import inline  # noqa: E402
from psurf_core.kernels.shadow import CLEAR  # noqa: E402
from psurf_core.render import RenderSettings, kernel_radius, pass_generators  # noqa: E402
from psurf_core.scene import SceneError  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.techniques import UnknownTechnique  # noqa: E402
from psurf_core.techniques.base import PassContext  # noqa: E402
from psurf_core.trace import trace  # noqa: E402
from ui.cli.common import add_resolution_flag, with_resolution  # noqa: E402

#: The walker variants of ``--ablate``, in the order of the first round.
VARIANTS = ("base", "novis", "nocontrib", "neither")


class BenchError(ValueError):
    """A spec or option this benchmark cannot measure (one line, exit code 2)."""


@inline
def _all_clear(G, x0, hit, medium, blockers):
    return CLEAR, CLEAR, CLEAR


@inline
def _distance(G, psi, s, s_min, hit, short, medium):
    # Not a constant: a constant value could let the compiler drop work the walker does
    # for every hit whatever the contribution is.
    return s


#: Ablated family records by ``id`` of the original, kept alive with it: the walkers are
#: cached by ``id(family)`` (``kernels.walk.walker``), so a freed variant's id must never be
#: reused for another variant in this process.
_ABLATED: dict = {}


def ablated(fam) -> dict:
    """``{variant: family record}`` for ``fam`` (a technique's ``compiled``), built once."""
    if id(fam) not in _ABLATED:
        rep = dataclasses.replace
        _ABLATED[id(fam)] = (fam, {
            "base": fam,
            "novis": rep(fam, visibility=_all_clear),
            "nocontrib": rep(fam, contribution=_distance),
            "neither": rep(fam, visibility=_all_clear, contribution=_distance)})
    return _ABLATED[id(fam)][1]


@contextmanager
def compiled_as(tech, fam):
    """``tech.compiled`` is ``fam`` inside the block; restored after (an instance attribute
    put back, or removed where the class supplied it)."""
    own = "compiled" in vars(tech)
    old = vars(tech).get("compiled")
    tech.compiled = fam
    try:
        yield
    finally:
        if own:
            tech.compiled = old
        else:
            del tech.compiled


@contextmanager
def instrumented(load_cap: bool = True):
    """Time ``fused._Run.spans`` and ``walk_chunk`` into each run's ``stats`` dict (keys
    ``spans``, ``walker`` and their ``_cpu``; ``threads_used``: the most threads a chunk ran
    on); without ``load_cap``, chunks use numba's thread count whatever the machine's load.
    Everything patched is restored on exit."""
    spans, walk_chunk, count = fused._Run.spans, fused._Run.walk_chunk, fused.thread_count

    def timed_spans(self):
        with Clock(self.stats, "spans"):
            return spans(self)

    def timed_walk(self, s, cand, a, b, threads, out=None):
        self.stats["threads_used"] = max(self.stats.get("threads_used", 0), threads)
        with Clock(self.stats, "walker"):
            return walk_chunk(self, s, cand, a, b, threads, out)

    fused._Run.spans, fused._Run.walk_chunk = timed_spans, timed_walk
    if not load_cap:
        fused.thread_count = numba.get_num_threads
    try:
        yield
    finally:
        fused._Run.spans, fused._Run.walk_chunk, fused.thread_count = spans, walk_chunk, count


def prepare(scene, spec: str, photons: int, seed: int = 0) -> list[tuple]:
    """Pass 0's inputs, traced and created once: per technique of ``spec``'s sets,
    ``(tech, prims, paths, rays, ctx, mis)`` (the arguments of ``fused_pass``)."""
    est = parse_estimator(spec, scene)
    settings = RenderSettings(photons=photons)
    blockers = blockers_of(scene)
    ray_rng, photon_ss = pass_generators(seed, 0)
    rays = camera_rays(scene, settings.spp, ray_rng, blockers=blockers)
    paths = trace(scene, photons, np.random.default_rng(photon_ss.spawn(1)[0]),
                  blockers=blockers)
    jobs = []
    for group, full in est.sets:
        mis = fused.MisSet(group, full, est.weighting) if len(group) > 1 else None
        for tech in group:
            if getattr(tech, "compiled", None) is None:
                raise BenchError(f"'{tech.name}' has no compiled walker (numpy stages only)")
            ctx = PassContext(scene, blockers, kernel_radius(tech, scene, settings, 0), 0,
                              settings.max_pairs)
            jobs.append((tech, tech.create(paths, ctx), paths, rays, ctx, mis))
    return jobs


def run_pass(jobs) -> dict:
    """One compiled pass of every job, timed (inside :func:`instrumented`): per technique
    the ``stats`` of its run plus ``pass`` / ``pass_cpu`` seconds."""
    res = {}
    for tech, prims, paths, rays, ctx, mis in jobs:
        st = res.setdefault(tech.name, {"candidates": 0, "hits": 0})
        out = np.zeros((len(rays), 3))
        with Clock(st, "pass"):
            run = fused.fused_pass(tech, prims, paths, rays, ctx, mis, emit=False, out=out,
                                   stats=st)
            if run is None:
                raise BenchError(f"'{tech.name}' takes no compiled walk on this scene (64 "
                                 "or fewer pixels see the medium, or a blocker has no bounds)")
            list(run)
    return res


_TIMES = ("pass", "spans", "walker")


def _ms(rounds: list[dict]) -> dict:
    """Medians of the rounds after the first, in ms, with the counts of the last round."""
    warm = rounds[1:]
    out = {}
    for k in _TIMES:
        for suffix in ("", "_cpu"):
            out[f"{k}{suffix}_ms"] = 1e3 * statistics.median(r.get(k + suffix, 0.0)
                                                             for r in warm)
    out["other_ms"] = out["pass_ms"] - out["spans_ms"] - out["walker_ms"]
    out["hits"], out["candidates"] = rounds[-1]["hits"], rounds[-1]["candidates"]
    out["hits_per_second"] = statistics.median(r["hits"] / max(r["pass"], 1e-12) for r in warm)
    out["threads_used"] = max(r.get("threads_used", 0) for r in warm)
    out["hits_each_round"] = [r["hits"] for r in rounds]
    return out


def _total(res: dict) -> dict:
    """One row summing every technique of a pass's ``run_pass`` result."""
    tot: dict = {}
    for st in res.values():
        for k, v in st.items():
            tot[k] = max(tot.get(k, 0), v) if k == "threads_used" else tot.get(k, 0) + v
    return tot


def breakdown(jobs, rounds: int) -> dict:
    """The default table: per technique and in total (:func:`_ms`)."""
    runs = [run_pass(jobs) for _ in range(rounds)]
    out = {name: _ms([r[name] for r in runs]) for name in runs[0]}
    out["total"] = _ms([_total(r) for r in runs])
    return out


def _alternating(jobs, rounds: int, keys, setup) -> dict:
    """``run_pass`` per key in each round, the order rotated every round, under ``setup(key)``
    (a context manager): per key the :func:`_ms` of its whole pass (every technique)."""
    runs: dict = {k: [] for k in keys}
    each: dict = {k: {} for k in keys}
    for r in range(rounds):
        order = list(keys[r % len(keys):]) + list(keys[:r % len(keys)])
        for k in order:
            with setup(k):
                res = run_pass(jobs)
            runs[k].append(_total(res))
            for name, st in res.items():
                each[k].setdefault(name, []).append(st)
    out = {k: _ms(v) for k, v in runs.items()}
    for k in keys:  # per technique too (its own pass in the set)
        out[k]["techniques"] = {name: _ms(v) for name, v in each[k].items()}
    return out


def ablate(jobs, rounds: int) -> dict:
    """``--ablate``: :data:`VARIANTS` in alternating rounds; every technique restored."""
    for tech, *_ in jobs:
        fam = tech.compiled
        if not all(hasattr(fam, f) for f in ("visibility", "contribution")):
            raise BenchError(f"'{tech.name}': its compiled record has no visibility / "
                             "contribution to leave out")

    @contextmanager
    def variant(name):
        with ExitStack() as stack:
            for tech, *_ in jobs:
                stack.enter_context(compiled_as(tech, ablated(tech.compiled)[name]))
            yield

    return _alternating(jobs, rounds, VARIANTS, variant)


def scaling(jobs, rounds: int) -> dict:
    """``--scaling``: the pass on 1 and 2 numba threads in alternating rounds, and the
    walker's wall ratio."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        raise BenchError("--scaling needs numba's 2 threads (NUMBA_NUM_THREADS is "
                         f"{numba.config.NUMBA_NUM_THREADS})")
    before = numba.get_num_threads()

    @contextmanager
    def threads(n):
        numba.set_num_threads(n)
        try:
            yield
        finally:
            numba.set_num_threads(before)

    out = _alternating(jobs, rounds, (1, 2), threads)
    res = {str(k): v for k, v in out.items()}
    res["walker_wall_ratio_1_to_2"] = out[1]["walker_ms"] / max(out[2]["walker_ms"], 1e-12)
    return res


def _row(name: str, m: dict) -> str:
    return (f"{name:<16} {m['pass_ms']:7.1f} {m['pass_cpu_ms']:7.1f} {m['spans_ms']:7.1f} "
            f"{m['spans_cpu_ms']:7.1f} {m['walker_ms']:7.1f} {m['walker_cpu_ms']:7.1f} "
            f"{m['other_ms']:7.1f} {m['hits']:>9} {m['candidates']:>10} "
            f"{m['hits_per_second']:9.3g} {m['threads_used']:>7}")


_HEAD = (f"{'':<16} {'pass':>7} {'cpu':>7} {'spans':>7} {'cpu':>7} {'walker':>7} {'cpu':>7} "
         f"{'other':>7} {'hits':>9} {'candidates':>10} {'hits/s':>9} {'threads':>7}")


def report(res: dict) -> None:
    """The tables of ``res`` (:func:`measure`'s result), in ms per pass."""
    print(f"# {res['scene']}, {res['spec']}, {res['photons']} photons (one batch), "
          f"{res['pixels']} pixels x {res['spp']} spp, numba on {res['threads']} thread(s); "
          f"medians of rounds 2..{res['rounds']}; wall and CPU ms per pass")
    print(_HEAD)
    for name, m in res["breakdown"].items():
        if name != "total" or len(res["breakdown"]) > 2:
            print(_row(name, m))
    if "ablate" in res:
        print("\n# --ablate: the walker rebuilt without its parts, alternating rounds")
        print(_HEAD)
        for name, m in res["ablate"].items():
            print(_row(name, m))
        base = res["ablate"]["base"]["pass_cpu_ms"]
        same = len({tuple(m["hits_each_round"]) for m in res["ablate"].values()}) == 1
        print("hits: " + ("the same in every variant and round" if same else
                          "DIFFER between variants (an ablation changed which rays hit)"))
        print("CPU ms per pass: " + ", ".join(
            f"{k} {m['pass_cpu_ms']:.1f} ({m['pass_cpu_ms'] - base:+.1f})"
            for k, m in res["ablate"].items()))
        print("walker CPU ns a hit, per technique (in its set): base, and what its shadow "
              "statuses (base - novis) and its contribution (base - nocontrib) cost")
        ab = res["ablate"]
        for name, m in ab["base"]["techniques"].items():
            h = max(m["hits"], 1)

            def ns(v, name=name, h=h):
                return 1e6 * ab[v]["techniques"][name]["walker_cpu_ms"] / h

            print(f"  {name:<22} {ns('base'):6.1f}  shadow {ns('base') - ns('novis'):5.1f}  "
                  f"contribution {ns('base') - ns('nocontrib'):5.1f}")
    if "scaling" in res:
        s = res["scaling"]
        print("\n# --scaling: numba on 1 and 2 threads, alternating rounds")
        print(_HEAD)
        for k in ("1", "2"):
            print(_row(f"{k} thread(s)", s[k]))
        print(f"walker wall ms: {s['1']['walker_ms']:.1f} on 1 thread, {s['2']['walker_ms']:.1f}"
              f" on 2 ({s['walker_wall_ratio_1_to_2']:.2f}x)")
        if s["2"]["threads_used"] < 2:
            print("note: no chunk ran on 2 threads (fewer than THREADED_MIN_PAIRS candidate "
                  "pairs, or no core free of other load: see --no-load-cap)")


def measure(args) -> dict:
    """Every table ``args`` asks for (see the module docstring), as a dict."""
    scene = with_resolution(load_scene(args.scene), args.resolution)
    if args.scatter is not None:
        scene = scene.with_scatter(*args.scatter)
    jobs = prepare(scene, args.spec, args.photons)
    numba.set_num_threads(args.threads)
    res = {"scene": args.scene, "spec": args.spec, "photons": args.photons,
           "rounds": args.rounds, "threads": args.threads, "pixels": scene.camera.n_pixels,
           "spp": RenderSettings().spp, "load_cap": not args.no_load_cap}
    with instrumented(load_cap=not args.no_load_cap):
        res["breakdown"] = breakdown(jobs, args.rounds)
        if args.ablate:
            res["ablate"] = ablate(jobs, args.rounds)
        if args.scaling:
            res["scaling"] = scaling(jobs, args.rounds)
    return res


def check_args(args) -> None:
    """Raise :class:`BenchError` unless ``args`` (``--rounds``, ``--photons``, ``--threads``)
    can be run: at least 2 rounds (the first is cold), a photon, numba's thread range."""
    if args.rounds < 2 or args.photons < 1:
        raise BenchError("--rounds must be at least 2 (the first is cold) and --photons "
                         "at least 1")
    if not 1 <= args.threads <= numba.config.NUMBA_NUM_THREADS:
        raise BenchError(f"--threads must be 1..{numba.config.NUMBA_NUM_THREADS}")


def write_json(path, res, prog: str) -> int:
    """``res`` as JSON at ``path`` (None: nothing); the exit code: 0, or 2 (with one line on
    stderr naming ``prog``) where it cannot be written."""
    if path:
        try:
            with open(path, "w") as f:
                json.dump(res, f, indent=1)
        except OSError as e:
            print(f"{prog}: --json: {e}", file=sys.stderr)
            return 2
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--spec", default="planes")
    ap.add_argument("--photons", type=int, default=5000)
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--ablate", action="store_true")
    ap.add_argument("--scaling", action="store_true")
    ap.add_argument("--no-load-cap", action="store_true",
                    help="chunks use numba's thread count whatever other processes use")
    ap.add_argument("--json", metavar="PATH")
    ap.add_argument("--scatter", type=int, nargs=2, metavar=("KMIN", "KMAX"),
                    help="the scatter range (default: the scene's)")
    add_resolution_flag(ap)
    args = ap.parse_args(argv)
    threads_before = numba.get_num_threads()
    try:
        check_args(args)
        res = measure(args)
    except (BenchError, SceneError, UnknownTechnique, OSError) as e:
        print(f"pass_breakdown: {e}", file=sys.stderr)
        return 2
    finally:
        numba.set_num_threads(threads_before)
    report(res)
    return write_json(args.json, res, "pass_breakdown")


if __name__ == "__main__":
    sys.exit(main())
