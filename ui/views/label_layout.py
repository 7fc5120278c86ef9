"""Where the 3D views' labels go on screen so that no label covers another or a labelled point
(plain numpy, no VTK).

VTK draws a point label as a box whose lower-left corner is at its anchor (with a margin of
a few pixels around the text). Labels of close points (a path vertex next to the light, hits
bunched on the query ray) therefore cover each other when each is only pushed a fixed distance
away from its point: the boxes are wider than the gaps. :func:`place` works in pixels, with
the camera the view will have and every label's measured size, and moves each label, in turn,
to the first spot around its point (nearest ring first) where its box overlaps neither the
boxes placed before it nor any labelled point.
"""

from __future__ import annotations

import numpy as np

#: Pixels a label's box reaches beyond its text (VTK's margin) plus the gap kept between two
#: boxes and between a box and a point.
PAD = 5.0
#: Half the side of the square kept free around every labelled point (pixels).
POINT_HALF = 5.0
#: Directions tried around a point (degrees, preferred first: above, then beside, then below)
#: and the rings (multiples of the first distance).
DIRECTIONS = (90, 45, 135, 0, 180, 315, 225, 270)
RINGS = (1.0, 1.7, 2.5, 3.5, 5.0)


def view_basis(camera):
    """``(position, forward, right, up)`` unit vectors of ``camera`` ``(position, focal point,
    view up)``."""
    pos, focal, up = (np.asarray(v, dtype=float) for v in camera)
    fwd = (focal - pos) / np.linalg.norm(focal - pos)
    up = up - (up @ fwd) * fwd
    up = up / np.linalg.norm(up)
    return pos, fwd, np.cross(fwd, up), up


def pixels_per_unit(depth, view) -> np.ndarray:
    """Screen pixels per world unit, in the plane parallel to the image at ``depth``;
    ``view = (width_px, height_px, vertical view angle in degrees)``."""
    half = np.tan(np.radians(float(view[2])) / 2.0)
    return 0.5 * float(view[1]) / (np.maximum(np.asarray(depth, dtype=float), 1e-9) * half)


def project(points, camera, view):
    """``(screen, depth)``: (N, 2) pixel positions relative to the viewport's centre (y up)
    and (N,) depths along the view of ``points`` (N, 3) (perspective)."""
    pos, fwd, right, up = view_basis(camera)
    d = np.asarray(points, dtype=float).reshape(-1, 3) - pos
    depth = d @ fwd
    k = pixels_per_unit(depth, view)
    return np.stack([(d @ right) * k, (d @ up) * k], axis=-1), depth


def _overlap(box, boxes) -> float:
    """Summed overlap area of ``box`` ``(x0, y0, x1, y1)`` with each row of ``boxes``."""
    if not len(boxes):
        return 0.0
    b = np.asarray(boxes)
    w = np.clip(np.minimum(box[2], b[:, 2]) - np.maximum(box[0], b[:, 0]), 0.0, None)
    h = np.clip(np.minimum(box[3], b[:, 3]) - np.maximum(box[1], b[:, 1]), 0.0, None)
    return float((w * h).sum())


def place(screen, sizes, dist_px: float):
    """``(anchors, leaders)``: (N, 2) pixel offsets, from their points' ``screen``
    positions, of the label anchors (the boxes' lower-left corners) and of the leader lines'
    ends (the point of each box nearest its point).

    Parameters
    ----------
    screen : (N, 2) float
        The labelled points on screen (pixels).
    sizes : (N, 2) float
        Each label's text ``(width, height)`` in pixels.
    dist_px : float
        How far from its point a label starts looking (the first ring).

    Each label in turn takes the first spot (ring by ring, :data:`DIRECTIONS` in order) whose
    box is clear of the boxes already placed and of every point; if there is none, the spot
    that overlaps least. The box is put on the side of the spot away from its point, so a
    label to the left ends where a label to the right begins.
    """
    screen = np.asarray(screen, dtype=float).reshape(-1, 2)
    sizes = np.asarray(sizes, dtype=float).reshape(-1, 2)
    points = np.column_stack([screen - POINT_HALF, screen + POINT_HALF])
    placed: list = []
    out = np.zeros_like(screen)
    lead = np.zeros_like(screen)
    for i, (s, (w, h)) in enumerate(zip(screen, sizes, strict=True)):
        best, best_cost = None, np.inf
        for ring in RINGS:
            for a in DIRECTIONS:
                c, si = np.cos(np.radians(a)), np.sin(np.radians(a))
                q = s + ring * dist_px * np.array([c, si])
                ax = q[0] if c > 0.3 else (q[0] - w if c < -0.3 else q[0] - 0.5 * w)
                ay = q[1] if si > 0.3 else (q[1] - h if si < -0.3 else q[1] - 0.5 * h)
                box = (ax - PAD, ay - PAD, ax + w + PAD, ay + h + PAD)
                cost = _overlap(box, placed) + _overlap(box, points)
                if cost < best_cost - 1e-9:
                    best, best_cost = (ax, ay, box), cost
                if best_cost == 0.0:
                    break
            if best_cost == 0.0:
                break
        ax, ay, box = best
        placed.append(box)
        out[i] = (ax - s[0], ay - s[1])
        lead[i] = (np.clip(s[0], ax, ax + w) - s[0], np.clip(s[1], ay, ay + h) - s[1])
    return out, lead


def world_offsets(points, sizes, camera, view, dist_px: float):
    """``(anchors, leaders)``: (N, 3) world offsets of :func:`place`'s anchors and leader
    ends for ``points`` (N, 3), in the plane parallel to the image through each point (so
    the offsets on screen are exact)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(pts):
        return np.zeros((0, 3)), np.zeros((0, 3))
    screen, depth = project(pts, camera, view)
    _, _, right, up = view_basis(camera)
    per_px = 1.0 / pixels_per_unit(depth, view)

    def world(off):
        return (off[:, :1] * right[None] + off[:, 1:] * up[None]) * per_px[:, None]

    anchors, leaders = place(screen, sizes, dist_px)
    return world(anchors), world(leaders)


def line_up(screen, direction, sizes, gap_px: float):
    """``(anchors, leaders)`` (N, 2) pixel positions for labels of points strung along a line
    on screen (hits on the query ray, ``screen`` in their order along it): one row of boxes
    parallel to the line on its upper side, in the same order, each box one box apart (its
    width or its height, whichever the line's slope makes the one that keeps them apart),
    ``gap_px`` off the line. Leaders end at the point of each box nearest its point.

    ``direction`` : the line's direction on screen (2,); ``sizes`` (N, 2) the texts' sizes.
    """
    screen = np.asarray(screen, dtype=float).reshape(-1, 2)
    sizes = np.asarray(sizes, dtype=float).reshape(-1, 2)
    u = np.asarray(direction, dtype=float)
    u = u / max(np.linalg.norm(u), 1e-9)
    n = np.array([-u[1], u[0]])
    if n[1] < 0 or (n[1] == 0 and n[0] < 0):  # the upper side
        n = -n
    w, h = sizes.max(axis=0) + 2.0 * PAD
    step = min(w / abs(u[0]) if abs(u[0]) > 1e-9 else np.inf,
               h / abs(u[1]) if abs(u[1]) > 1e-9 else np.inf)
    # centres of the boxes: along the line about the points' middle, off it by half a box
    # (measured across the line) and the gap
    off = 0.5 * (w * abs(n[0]) + h * abs(n[1])) + gap_px
    k = np.arange(len(screen)) - 0.5 * (len(screen) - 1)
    mid = screen.mean(axis=0) + off * n
    centres = mid[None] + k[:, None] * step * u[None]
    anchors = centres - 0.5 * sizes
    leaders = np.column_stack([np.clip(screen[:, 0], anchors[:, 0], anchors[:, 0] + sizes[:, 0]),
                               np.clip(screen[:, 1], anchors[:, 1], anchors[:, 1] + sizes[:, 1])])
    return anchors, leaders
