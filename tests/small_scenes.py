"""The small scene the estimator tests build in Python, and the lights they share.

:func:`make_scene` is the unit box of medium (``sigma_s = 0.8``, ``sigma_a = 0.2``, isotropic
unless ``g`` is given) seen by a 40-degree camera four units away along -z, as
``tests/tiny_scene.py`` writes it as scene-file text; its few pixels keep oracles cheap.
The lights are chosen so that no symmetry of the box hides a bug: an off-centre point light of
coloured intensity, SCENES.md's default area light, a tilted parallelogram whose edges are not
orthogonal, and a closed tetrahedron.
"""

from __future__ import annotations

import numpy as np

from psurf_core.scene import AreaLight, Camera, Medium, MeshLight, Phase, PointLight, Scene

#: Default image size (pixels): enough for per-pixel oracles, few enough for 1D quadratures.
W, H = 8, 6


def make_scene(lights, occluders=(), g=0.0, sigma_s=0.8, sigma_a=0.2, kmin=1, kmax=1, *,
               size=(W, H), position=(0.0, 0.0, -4.0), fov=40.0) -> Scene:
    """The unit box of medium with ``lights`` and ``occluders``, scatter window ``[kmin, kmax]``.

    Parameters
    ----------
    lights, occluders : sequence
    g : float
        Henyey-Greenstein asymmetry (0: the isotropic phase function).
    sigma_s, sigma_a : float
        Scattering and absorption coefficients (1 / scene unit).
    kmin, kmax : int
        The scene's ``min_scatter`` and ``max_scatter``.
    size : (2,) int
        Image width and height in pixels.
    position : (3,) float
        Camera position; the camera looks at the box centre with +y up.
    fov : float
        Vertical field of view in degrees.
    """
    cam = Camera(np.array(position, float), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov, *size)
    phase = Phase("hg", g) if g else Phase()
    med = Medium(-np.ones(3), np.ones(3), sigma_s, sigma_a, phase)
    return Scene(cam, med, tuple(lights), tuple(occluders), kmin, kmax)


#: Off-centre point light, coloured intensity (W/sr); its axis +y orients the ss-* surfaces.
POINT = PointLight(np.array([0.3, 0.4, 0.1]), np.array([4.0, 2.0, 1.0]), np.array([0.0, 1.0, 0.0]))

#: SCENES.md's default area light: 0.6 x 0.6 just below the box's top, facing down.
TOP_AREA = AreaLight(corner=np.array([-0.3, 0.95, -0.3]), edge_u=np.array([0.6, 0.0, 0.0]),
                     edge_v=np.array([0.0, 0.0, 0.6]), radiance=np.array([3.0, 3.0, 3.0]))

#: Tilted parallelogram (its edges are not orthogonal), so that no axis alignment hides an
#: orientation bug.
TILTED_AREA = AreaLight(
    corner=np.array([-0.35, 0.55, 0.0]),
    edge_u=np.array([0.6, 0.1, 0.0]),
    edge_v=np.array([0.0, 0.15, 0.5]),
    radiance=np.array([3.0, 2.0, 1.5]),
)

#: A closed tetrahedron (outward, counter-clockwise faces): convex, so a front-facing point is
#: always visible from an outside vertex (a brute-force quadrature needs no visibility term).
TETRA_VERTICES = np.array([[0.2, -0.5, 0.3], [0.6, -0.5, 0.3], [0.4, -0.5, 0.65],
                           [0.4, -0.15, 0.45]])
_FACES = [(0, 3, 1), (1, 3, 2), (2, 3, 0), (0, 1, 2)]
TETRA = MeshLight(np.array([TETRA_VERTICES[list(f)] for f in _FACES]), np.array([2.0, 2.5, 3.0]))
