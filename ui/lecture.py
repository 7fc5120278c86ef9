"""Lecture mode: the tutorials' key states in the app, one click each (``python app.py lecture``).

Every state is pinned (scene, scatter window, estimator, seed, picked pixel, stage, camera,
photons and passes), so the same click shows the same picture in every class: the picture
is a function of the state alone, and ``tests/test_lecture.py`` checks each one against a
committed baseline. The window is the app's own (:mod:`ui.window`: 3D view, render,
variance and stage panel); lecture mode only replaces the title and caption with the
state's, puts the camera where the state says, and binds

``->`` / ``<-``  next / previous state,   ``r`` back to the pinned camera,
``space``        play / pause progressive rendering (more passes of the same seed),
``s``            screenshot,   ``h`` help,   ``q`` quit.

``app.py`` wires it in with::

    from ui.lecture import add_lecture_parser
    add_lecture_parser(sub)      # sets func=run_lecture_cmd

and ``python app.py lecture [--state N] [--screenshot OUT.png] [--size W,H] [--windowed]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .stepper import Stepper

PROG = "psurf"
ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SIZE = (1600, 900)

#: Camera positions ``(position, focal_point, view_up)``. ``OVERVIEW`` is
#: ``ui.scene_view.overview_camera`` of the bundled scenes (camera, frustum and box);
#: ``BOX`` looks at the medium box from the same side; ``CLOSE`` closer still.
OVERVIEW = ((-5.885, 4.326, -9.047), (0.083, 0.347, -1.089), (0.207, 0.862, 0.276))
BOX = ((-3.064, 2.143, -4.085), (0.0, 0.1, 0.0), (0.207, 0.862, 0.276))
CLOSE = ((-2.507, 1.871, -3.343), (0.0, 0.2, 0.0), (0.207, 0.862, 0.276))


@dataclass(frozen=True)
class LectureState:
    """One pinned picture of the lecture.

    Attributes
    ----------
    tutorial : int
        The tutorial (``tutorials/NN_*.py``) the state illustrates.
    title, caption : str
        Shown at the top of the 3D view (the caption wraps at 78 characters).
    scene : str
        Scene file, relative to the repository root.
    estimator : str
        A photon estimator spec (``planes``, ``mis:A+B``, ...).
    stage : str
        ``trace``, ``create``, ``intersect``, ``evaluate`` or ``reconstruct``.
    seed : int
    pixel : (int, int)
        Picked pixel ``(X, Y)``: column from the left, row from the top.
    scatter : (int, int) or None
        ``(min_scatter, max_scatter)`` replacing the scene's ``[render]`` window.
    camera : ((3,), (3,), (3,))
        Position, focal point and view-up of the 3D view.
    photons, passes : int
        Per-pass photons and the passes rendered for the image panels (pass 0 is inspected).
    hit : int
        Reconstruct: the hit shown, numbered as in the evaluate table.
    n_paths : int
        Photon subpaths drawn in Trace and Create.
    """

    tutorial: int
    title: str
    caption: str
    scene: str
    estimator: str
    stage: str
    seed: int = 0
    pixel: tuple = (32, 24)
    scatter: tuple | None = None
    camera: tuple = OVERVIEW
    photons: int = 500
    passes: int = 3
    hit: int = 0
    n_paths: int = 24


_MULTI = "mis:plane-t1t2+sphere+cone+cylinder"

#: The lecture, in order (the talk's storyline, tutorial by tutorial).
STATES: tuple[LectureState, ...] = (
    LectureState(
        1, "The problem: a light, a medium, a camera",
        "Photons leave the light and fly through the medium as if it were infinite. A pixel "
        "measures the light scattered towards the camera along its ray, summed over every "
        "number K of scattering events.",
        "scenes/point.toml", "beams", "trace", seed=1, pixel=(37, 17), photons=2000, passes=4,
        n_paths=40),
    LectureState(
        1, "Full transport vs the k-th bounce",
        "The same machinery restricted to K = 2: only light that scattered exactly twice. "
        "The full image is the sum over K of such bounce images (tutorial 1).",
        "scenes/area.toml", "beams", "trace", seed=1, pixel=(32, 12), scatter=(2, 2),
        photons=2000, passes=4, n_paths=30),
    LectureState(
        2, "Photon points: a 3D blur",
        "A photon vertex never lies exactly on a camera ray, so classic photon mapping blurs "
        "it into a sphere of radius r: smooth images, biased by the blur.",
        "scenes/point.toml", "points", "create", seed=2, pixel=(37, 17), photons=2000,
        passes=4, camera=BOX, n_paths=60),
    LectureState(
        2, "Photon beams: a 1D blur",
        "Keeping the whole photon segment leaves one dimension to blur: a thin tube. Less "
        "blur, less bias for the same noise.",
        "scenes/point.toml", "beams", "create", seed=2, pixel=(37, 17), photons=2000,
        passes=4, camera=BOX, n_paths=30),
    LectureState(
        2, "Photon planes: no blur, unbiased",
        "Integrating the last two distances t1, t2 sweeps a plane: the camera ray meets it "
        "exactly, no kernel needed. Arrows: psi (black) and the scaled normal n (red).",
        "scenes/area.toml", "planes", "intersect", seed=3, pixel=(32, 16), scatter=(2, 2),
        photons=1000, passes=4, camera=BOX),
    LectureState(
        2, "Photon planes' weakness: 1/|n.psi|",
        "Each hit contributes f / |n.psi|. A ray grazing a plane divides by almost zero: "
        "rare, huge contributions (fireflies) and infinite variance.",
        "scenes/area.toml", "planes", "evaluate", seed=3, pixel=(32, 16), scatter=(2, 2),
        photons=1000, passes=4, camera=BOX),
    LectureState(
        2, "Photon planes' other gap: single scattering",
        "A plane needs two photon segments, so it cannot estimate light that scattered "
        "once. Restricted to K = 1, planes create nothing and render black.",
        "scenes/point.toml", "planes", "create", seed=3, pixel=(37, 17), scatter=(1, 1),
        photons=1000, passes=2, camera=BOX),
    LectureState(
        3, "The delta^3 derivation: the Jacobian is |n.psi|",
        "Integrate the 3D delta over two photon dimensions and the ray distance s: the "
        "Jacobian is |det[dx0/dxi1, dx0/dxi2, -psi]| = |n.psi| (tutorial 3 checks it by "
        "finite differences).",
        "scenes/point.toml", "plane-t1t2-short", "intersect", seed=4, pixel=(30, 20),
        scatter=(2, 2), photons=1000, passes=3, camera=BOX),
    LectureState(
        4, "Photon surfaces: sphere, cone, cylinder",
        "Other pairs of dimensions sweep other surfaces: [cos th1, ph1] a sphere about x1, "
        "[t1, ph1] a cone about w2, [t2, ph1] a cylinder (short variants drawn).",
        "scenes/point.toml", "mis:sphere+cone-short+cylinder-short", "create", seed=5,
        pixel=(30, 20), scatter=(2, 2), photons=300, passes=2, camera=BOX, n_paths=3),
    LectureState(
        4, "More surfaces: disk, hyperboloid, torus",
        "[t1, cos th1] a half-plane disk; [t1, ph2] a ray revolved about the previous "
        "direction (hyperboloid); [cos th1, ph2] a revolved circle (torus).",
        "scenes/point.toml", "mis:disk-short+hyperboloid-short+torus", "create", seed=5,
        pixel=(30, 20), scatter=(2, 2), photons=150, passes=2, camera=BOX, n_paths=2),
    LectureState(
        5, "Single scattering from a point light",
        "With one segment the surfaces sit on the light: a sphere of radius T, a cone and a "
        "disk about the light's axis a. The single-scattering gap closes.",
        "scenes/point.toml", "mis:ss-sphere+ss-cone-short+ss-disk-short", "create", seed=6,
        pixel=(30, 20), scatter=(1, 1), photons=300, passes=2, camera=CLOSE, n_paths=4),
    LectureState(
        5, "Area light: the [u,v], [u,t] and [v,t] planes",
        "[u, v]: the light itself, moved by T w. [u, t] and [v, t]: strips swept by the "
        "light's edges along the photon's direction.",
        "scenes/area.toml", "mis:ss-plane-uv+ss-plane-ut-short+ss-plane-vt-short", "create",
        seed=6, pixel=(32, 10), scatter=(1, 1), photons=500, passes=2, camera=BOX,
        n_paths=4),
    LectureState(
        5, "Mesh light: translated copies of the emitter",
        "For a mesh light the [u, v] surface of each photon is its emitting triangle, "
        "translated by T w: a cloud of copies of the emitter (the talk's bunny light).",
        "scenes/mesh_light.toml", "ss-plane-uv", "create", seed=6, pixel=(32, 14),
        scatter=(1, 1), photons=1000, passes=3, camera=CLOSE, n_paths=120),
    LectureState(
        6, "MIS: every hit is weighted",
        "Each surface is a sampling technique. A hit is weighted by Q_i / sum Q_j, all "
        "densities on the same path: column w. The weighted hits sum to the pixel.",
        "scenes/area.toml", _MULTI, "evaluate", seed=7, pixel=(32, 16), scatter=(2, 2),
        photons=200, passes=2, camera=BOX),
    LectureState(
        6, "Reconstruct & Evaluate",
        "A cone hit fixes t1 and ph1, so the whole path is known (thick). Every member "
        "evaluates its Q on it; the sphere and the cylinder found the same path (#15, #17): "
        "same Q's, same weights.",
        "scenes/area.toml", _MULTI, "reconstruct", seed=7, pixel=(32, 16), scatter=(2, 2),
        photons=200, passes=2, camera=BOX, hit=16),
    LectureState(
        7, "Equal photons: the baseline (photon planes)",
        "Photon planes, 300 photons per pass: note the variance panel's range (per pass, "
        "log scale). Next: the paper's MIS with the same photons.",
        "scenes/area.toml", "planes", "evaluate", seed=8, pixel=(32, 16), scatter=(2, 2),
        photons=300, passes=2, camera=BOX),
    LectureState(
        7, "Equal photons: ours (MIS of planes, cone, cylinder)",
        "Same photons: about 0.1x the variance per photon (tutorial 7). At equal time "
        "psurf's numpy MIS loses: each photon costs ~25x more (the paper's C++: 0.229x).",
        "scenes/area.toml", "paper-multi", "evaluate", seed=8, pixel=(32, 16), scatter=(2, 2),
        photons=300, passes=2, camera=BOX),
    LectureState(
        8, "Long surfaces: expected-value transmittance",
        "A long cone lets t1 run to the box wall and multiplies by exp(-st t1) exactly.",
        "scenes/area.toml", "cone", "create", seed=9, pixel=(32, 16), scatter=(2, 2),
        photons=500, passes=3, camera=BOX, n_paths=5),
    LectureState(
        8, "Short surfaces: track-length transmittance",
        "A short cone stops at the photon's own flight T1 and drops the exponential: "
        "P(T1 > t1) = exp(-st t1), so it is still unbiased, with fewer and cheaper hits.",
        "scenes/area.toml", "cone-short", "create", seed=9, pixel=(32, 16), scatter=(2, 2),
        photons=500, passes=3, camera=BOX, n_paths=5),
)

HELP = """lecture keys
  -> / <-   next / previous state
  r         back to the pinned camera
  space     play / pause progressive rendering
  s         screenshot (PNG in the current folder)
  h         this help
  q         quit"""


# --------------------------------------------------------------------------- building
@dataclass
class LectureStepper(Stepper):
    """A :class:`ui.stepper.Stepper` that shows a lecture state's title and caption."""

    lecture_title: str = ""
    lecture_caption: str = ""

    @property
    def title(self) -> str:
        return self.lecture_title

    @property
    def caption(self) -> str:
        return self.lecture_caption


def _stepper(state: LectureState) -> LectureStepper:
    s = LectureStepper(lecture_title=state.title, lecture_caption=state.caption)
    s.go(state.stage)
    return s


def load_state_scene(state: LectureState):
    """The state's scene, with its scatter window applied."""
    from psurf_core import load_scene

    scene = load_scene(ROOT / state.scene)
    if state.scatter is not None:
        scene = scene.with_scatter(*state.scatter)
    return scene


def build_view(state: LectureState):
    """The :class:`ui.window.ViewState` of a lecture state (renders its passes, inspects its
    pixel in pass 0): what :func:`ui.window.build_state` does, plus the scatter window."""
    from psurf_core import RenderSettings, parse_estimator
    from psurf_core.inspect import inspect_pixel
    from psurf_core.render import render

    from .window import ViewState

    scene = load_state_scene(state)
    est = parse_estimator(state.estimator, scene)
    settings = RenderSettings(photons=int(state.photons), spp=1)
    inspection = inspect_pixel(scene, est, state.seed, 0, state.pixel, settings)
    res = render(scene, est, settings, passes=max(int(state.passes), 1), seed=state.seed)
    view = ViewState(scene_path=str(ROOT / state.scene), scene=scene, estimator=est,
                     seed=int(state.seed), settings=settings, pixel_xy=tuple(state.pixel),
                     acc=res.accumulator, inspection=inspection, stepper=_stepper(state),
                     initial_passes=max(int(state.passes), 1))
    view.hit = int(state.hit)
    view.n_paths = int(state.n_paths)
    return view


def compose_state(plotter, state: LectureState, view, index: int, *,
                  keep_camera: bool = False) -> None:
    """Draw lecture state ``index`` (the window's panels, the state's camera and counter)."""
    from . import scene_view
    from .window import compose

    # Once a window has been shown, pyvista renders after every added actor; one picture is
    # dozens of actors, so render once at the end instead (the caller renders).
    suppressed = plotter.suppress_rendering
    plotter.suppress_rendering = True
    try:
        compose(plotter, view, keep_camera=keep_camera)
        plotter.subplot(0, 0)
        if not keep_camera:
            plotter.camera_position = [tuple(map(float, v)) for v in state.camera]
            plotter.renderer.ResetCameraClippingRange()
        scene_view.add_text(plotter, f"{index + 1}/{len(STATES)}  (tutorial {state.tutorial})"
                                     "  <- ->", 0.985, 0.05, scene_view.FONT_SMALL,
                            name="stage-hint", colour="#555555", align="right")
        if view.show_help:
            scene_view.add_text(plotter, HELP, 0.04, 0.78, scene_view.FONT, mono=True,
                                box=True, name="help")
    finally:
        plotter.suppress_rendering = suppressed


def check_index(index: int) -> int:
    """``index`` (0-based) if it names a state, else ``IndexError`` naming the valid range."""
    if not 0 <= int(index) < len(STATES):
        raise IndexError(f"state {int(index) + 1} does not exist (there are {len(STATES)}: "
                         f"1..{len(STATES)})")
    return int(index)


# --------------------------------------------------------------------------- public API
def lecture_screenshot(state_index: int, out: str, size=DEFAULT_SIZE) -> np.ndarray:
    """Render lecture state ``state_index`` (0-based) off-screen and write it to ``out``.

    Returns
    -------
    (H, W, 3) uint8
        The image written (the same picture for the same state, size and machine setup).
    """
    import imageio.v3 as iio
    import pyvista as pv

    from .window import make_plotter

    state = STATES[check_index(state_index)]
    view = build_view(state)
    pv.OFF_SCREEN = True
    plotter = make_plotter(tuple(size), off_screen=True)
    try:
        compose_state(plotter, state, view, state_index)
        img = plotter.screenshot(None, return_img=True)
    finally:
        plotter.close()
    folder = os.path.dirname(os.path.abspath(out))
    os.makedirs(folder, exist_ok=True)
    iio.imwrite(out, img)
    return img


@dataclass
class Lecture:
    """Key bindings of the lecture window (methods also work on an off-screen plotter)."""

    plotter: object
    index: int = 0
    view: object = None
    playing: bool = False
    cache: dict = field(default_factory=dict)

    @property
    def state(self) -> LectureState:
        return STATES[self.index]

    def show(self, index: int) -> None:
        """Go to state ``index``: its pinned picture (built once, then reused; a state whose
        rendering was continued with ``space`` is rebuilt, so a click always shows the same
        picture)."""
        self.index = check_index(index)
        view = self.cache.get(self.index)
        if view is None or view.acc.n != max(int(self.state.passes), 1):
            view = self.cache[self.index] = build_view(self.state)
        view.show_help, view.message = False, ""
        self.view = view
        self.playing = False
        self._draw(keep_camera=False)

    def _draw(self, keep_camera: bool = True) -> None:
        compose_state(self.plotter, self.state, self.view, self.index, keep_camera=keep_camera)
        self.plotter.render()

    def next(self) -> None:
        self.show(min(self.index + 1, len(STATES) - 1))

    def previous(self) -> None:
        self.show(max(self.index - 1, 0))

    def reset_camera(self) -> None:
        self._draw(keep_camera=False)

    def toggle_help(self) -> None:
        self.view.show_help = not self.view.show_help
        self._draw()

    def toggle_play(self) -> None:
        self.playing = not self.playing
        self.view.message = "playing: one pass per tick" if self.playing else "paused"
        self._draw()

    def save(self) -> str:
        out = os.path.abspath(f"psurf-lecture-{self.index + 1:02d}.png")
        self.plotter.screenshot(out)
        return out

    def tick(self, _step=None) -> None:
        """One more pass of the state's own seed (the picture grows, still reproducible)."""
        if not self.playing:
            return
        from psurf_core.render import render_pass

        v = self.view
        v.acc.add(render_pass(v.scene, v.estimator, v.acc.n, v.seed, v.settings))
        v.message = f"playing: {v.acc.n} passes"
        self._draw()

    def bind(self) -> None:
        p = self.plotter
        if p.iren is None:  # off-screen: nothing to bind
            return
        p.iren.interactor.RemoveObservers("CharEvent")  # VTK's own shortcuts (w, s, r, ...)
        for key in ("Left", "Right", "Up", "Down"):
            p.clear_events_for_key(key, raise_on_missing=False)
        keys = {"Right": self.next, "Left": self.previous, "Next": self.next,
                "Prior": self.previous, "r": self.reset_camera, "h": self.toggle_help,
                "space": self.toggle_play, "s": self.save}
        for k, fn in keys.items():
            p.add_key_event(k, fn)
        p.add_timer_event(max_steps=10**9, duration=250, callback=self.tick)


def _screen_size():
    """The display's size in pixels, or None when unknown."""
    try:
        import vtk

        w = vtk.vtkRenderWindow()
        w.SetOffScreenRendering(False)
        size = tuple(int(v) for v in w.GetScreenSize())
        w.Finalize()
        return size if min(size) >= 300 else None
    except Exception:
        return None


def run_lecture(start: int = 0, size=None, full_screen: bool = True) -> None:
    """Open the lecture window at state ``start`` (0-based); blocks until it is closed."""
    from .window import make_plotter

    check_index(start)
    if size is None:
        size = (_screen_size() if full_screen else None) or DEFAULT_SIZE
    plotter = make_plotter(tuple(size))
    lecture = Lecture(plotter)
    lecture.show(start)
    lecture.bind()
    plotter.show(title="psurf lecture - photon surfaces", full_screen=full_screen)


# --------------------------------------------------------------------------- command line
def _fail(message: str) -> int:
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


def _state_number(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer in 1..{len(STATES)}, "
                                         f"got {text!r}") from None
    if not 1 <= v <= len(STATES):
        raise argparse.ArgumentTypeError(f"must be in 1..{len(STATES)} (there are "
                                         f"{len(STATES)} states), got {v}")
    return v


def _size(text: str) -> tuple[int, int]:
    parts = text.replace("x", ",").split(",")
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be W,H (two integers >= 64), got {text!r}") \
            from None
    if w < 64 or h < 64:
        raise argparse.ArgumentTypeError(f"must be W,H (two integers >= 64), got {text!r}")
    return w, h


def state_list() -> str:
    """One line per state, for ``--help`` and ``--list``."""
    return "\n".join(f"  {i + 1:2d}  [tutorial {s.tutorial}] {s.title}"
                     for i, s in enumerate(STATES))


def add_lecture_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``lecture`` subcommand to ``subparsers`` (``func=run_lecture_cmd``)."""
    p = subparsers.add_parser(
        "lecture",
        help="walk through the tutorials' key states, full-screen (-> / <-)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(textwrap.fill(
            "The tutorials' key states in the app, full-screen, with captions; -> / <- move "
            "between states. Every state is pinned (scene, seed, camera, stage, photons, "
            "passes): the same state shows the same picture.", width=88)
            + "\n\nstates:\n" + state_list()),
    )
    p.add_argument("--state", type=_state_number, default=1, metavar="N",
                   help=f"state to open (or to screenshot), 1..{len(STATES)} (default 1)")
    p.add_argument("--screenshot", default=None, metavar="OUT.png",
                   help="render state N off-screen to OUT.png instead of opening the window")
    p.add_argument("--size", type=_size, default=None, metavar="W,H",
                   help="window / screenshot size (default: the screen, or 1600,900)")
    p.add_argument("--windowed", action="store_true", help="a window instead of full screen")
    p.add_argument("--list", action="store_true", help="print the states and exit")
    p.set_defaults(func=run_lecture_cmd)
    return p


def run_lecture_cmd(args) -> int:
    """Run ``lecture``; returns 0, or 2 after one ``psurf: error:`` line."""
    if getattr(args, "list", False):
        print(state_list())
        return 0
    index = int(args.state) - 1
    if args.screenshot is not None:
        out = args.screenshot
        if not out.lower().endswith(".png"):
            return _fail(f"--screenshot {out}: must end in .png")
        folder = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(folder):
            return _fail(f"--screenshot {out}: directory {folder} does not exist")
        try:
            lecture_screenshot(index, out, size=args.size or DEFAULT_SIZE)
        except (ImportError, RuntimeError) as e:
            return _fail(f"off-screen rendering is unavailable ({type(e).__name__}: {e}); "
                         "it needs VTK with EGL or OSMesa (libegl1 / libosmesa6)")
        print(f"wrote {out}")
        return 0
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return _fail("lecture: no display (DISPLAY / WAYLAND_DISPLAY unset); use "
                     "--screenshot OUT.png to render a state off-screen")
    run_lecture(index, size=args.size, full_screen=not args.windowed)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry (``python -m ui.lecture ...``) until ``app.py`` wires it."""

    class _Parser(argparse.ArgumentParser):
        def error(self, message):
            raise SystemExit(_fail(message))

    top = _Parser(prog=PROG)
    sub = top.add_subparsers(dest="command", parser_class=_Parser)
    add_lecture_parser(sub)
    args = top.parse_args(["lecture", *(argv if argv is not None else sys.argv[1:])])
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
