"""The lecture's states: the tutorials' key pictures, each pinned (scene, scatter window,
estimator, seed, picked pixel, stage, camera, photons and passes), in the talk's order.

Plain data (no rendering, no VTK): the ``lecture`` command (:mod:`ui.cli.lecture`) lists and
checks them from here, and :mod:`ui.views.lecture` draws them. The picture of a state is a
function of the state alone; ``tests/test_lecture.py`` checks each one against a committed
baseline.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: The repository root (state scenes are relative to it).
ROOT = Path(__file__).resolve().parents[2]

#: Camera positions ``(position, focal_point, view_up)``. ``OVERVIEW`` is
#: ``ui.views.scene_view.overview_camera`` of the bundled scenes (camera, frustum and box);
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
    camera : ((3,), (3,), (3,)) or None
        Position, focal point and view-up of the 3D view; None: the stage's own view
        (Reconstruct frames the path of the hit it shows).
    photons, passes : int
        Per-pass photons and the passes rendered for the image panels (pass 0 is inspected).
    hit : int
        Reconstruct: the hit shown, numbered as in the evaluate table.
    n_paths : int
        Photon subpaths drawn in Trace and Create.
    var_clim : (float, float) or None
        The variance panel's colour range; states that compare estimators pin the same one
        (None: the map's own range).
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
    camera: tuple | None = OVERVIEW
    photons: int = 500
    passes: int = 3
    hit: int = 0
    n_paths: int = 24
    var_clim: tuple | None = None


_MULTI = "mis:plane-t1t2+sphere+cone+cylinder"
#: The variance range shared by the equal-photons pair (planes vs paper-multi, states 16-17):
#: one colour scale, so the two maps compare by colour.
_EQUAL_PHOTONS_CLIM = (1e-11, 1e-3)

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
        "exactly, no kernel needed. Arrows: psi (grey) and the scaled normal n (black).",
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
        photons=200, passes=2, camera=None, hit=16),
    LectureState(
        7, "Equal photons: the baseline (photon planes)",
        "Photon planes, 300 photons per pass: the variance panel (per pass, log scale) shares "
        "its colour scale with the next state's. Next: the paper's MIS with the same photons.",
        "scenes/area.toml", "planes", "evaluate", seed=8, pixel=(32, 16), scatter=(2, 2),
        photons=300, passes=2, camera=BOX, var_clim=_EQUAL_PHOTONS_CLIM),
    LectureState(
        7, "Equal photons: ours (MIS of planes, cone, cylinder)",
        "Same photons, same colour scale: far less variance per photon. Whether that wins at "
        "equal time depends on what a photon costs; tutorial 7 and the window's equal-time "
        "panels measure both on this machine.",
        "scenes/area.toml", "paper-multi", "evaluate", seed=8, pixel=(32, 16), scatter=(2, 2),
        photons=300, passes=2, camera=BOX, var_clim=_EQUAL_PHOTONS_CLIM),
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


#: The longest caption: the window's title block makes room for it (no state is cut).
CAPTION_CHARS = max(len(s.caption) for s in STATES)


def check_index(index: int) -> int:
    """``index`` (0-based) if it names a state, else ``IndexError`` naming the valid range."""
    if not 0 <= int(index) < len(STATES):
        raise IndexError(f"state {int(index) + 1} does not exist (there are {len(STATES)}: "
                         f"1..{len(STATES)})")
    return int(index)


def state_list() -> str:
    """One line per state, for ``--help`` and ``--list``."""
    return "\n".join(f"  {i + 1:2d}  [tutorial {s.tutorial}] {s.title}"
                     for i, s in enumerate(STATES))


def load_state_scene(state: LectureState):
    """The state's scene, with its scatter window applied."""
    from psurf_core import load_scene

    scene = load_scene(ROOT / state.scene)
    if state.scatter is not None:
        scene = scene.with_scatter(*state.scatter)
    return scene
