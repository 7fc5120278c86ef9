"""The colours of every view, legend and tutorial: one colour per technique, colour-blind safe.

Plain Python (no VTK): the views, the window's chips, the tutorials' matplotlib figures and the
browser version take their colours from here, so a technique looks the same everywhere.

The palette is Okabe & Ito's (2008, "Color Universal Design"), whose eight colours stay
distinguishable with every common colour-vision deficiency. A technique's colour is fixed by
its *name* (never by its position in an estimator, so switching an MIS member off changes no
other member's colour):

* the surface a technique sweeps decides the colour: the three generalized planes, sphere,
  cone, cylinder and disk each have their own, and within each of the paper's presets
  (``paper-single``, ``paper-multi``) every member has a different one;
* a ``-short`` technique shares its long twin's colour (the same surface, cut at the photon's
  own flight), a single-scattering technique the colour of its surface (``ss-cone`` is a cone);
  the legends name the technique, so the two never need telling apart by colour alone.

Colours never carry a second meaning: a member chip that is on is filled with its technique's
colour, one that is off is white with grey text (``chip_colours``); what is not a technique
(the query ray, hits, normals, the reconstructed path, lights, occluders) is drawn in black,
white, greys or a pale cream.
"""

from __future__ import annotations

#: Okabe & Ito (2008): distinguishable with every common colour-vision deficiency.
OKABE_ITO = {
    "black": "#000000",
    "orange": "#E69F00",
    "sky_blue": "#56B4E9",
    "green": "#009E73",
    "yellow": "#F0E442",
    "blue": "#0072B2",
    "vermillion": "#D55E00",
    "purple": "#CC79A7",
    "grey": "#999999",
}

_O = OKABE_ITO

#: Colour of every technique (long names; ``-short`` and single-scattering variants map here).
TECHNIQUE_COLOURS = {
    # photon planes and the generalized planes (paper-multi: t1t2, t1t3, t2t3, cone, cylinder)
    "plane-t1t2": _O["blue"],
    "plane-t1t3": _O["sky_blue"],
    "plane-t2t3": _O["purple"],
    "cone": _O["vermillion"],
    "cylinder": _O["orange"],
    "sphere": _O["green"],
    "disk": _O["yellow"],
    "hyperboloid": _O["purple"],
    "torus": _O["sky_blue"],
    # single scattering (paper-single: uv, ut, vt, cone, sphere, disk: six different colours)
    "ss-plane-uv": _O["blue"],
    "ss-plane-ut": _O["sky_blue"],
    "ss-plane-vt": _O["purple"],
    "ss-sphere": _O["green"],
    "ss-cone": _O["vermillion"],
    "ss-disk": _O["yellow"],
    # kernel baselines
    "points": _O["purple"],
    "bre": _O["sky_blue"],
    "beams": _O["green"],
    "beams-long": _O["green"],
}
#: A technique this table does not know (a new family): grey, and its legend says its name.
FALLBACK_COLOUR = _O["grey"]


def base_name(name: str) -> str:
    """The long technique a name stands for (``plane-t1t2-short`` -> ``plane-t1t2``)."""
    name = str(name)
    return name[: -len("-short")] if name.endswith("-short") else name


def technique_colour(name: str) -> str:
    """The colour of technique ``name`` (hex), the same in every view, legend and tutorial."""
    return TECHNIQUE_COLOURS.get(base_name(name), FALLBACK_COLOUR)


def luminance(colour: str) -> float:
    """Relative luminance (0 black .. 1 white) of a ``#RRGGBB`` colour (Rec. 709 weights on
    the sRGB values: enough to choose black or white text on it)."""
    c = colour.lstrip("#")
    r, g, b = (int(c[i:i + 2], 16) / 255.0 for i in (0, 2, 4))
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def text_on(colour: str) -> str:
    """Black or white, whichever reads on ``colour``."""
    return "#000000" if luminance(colour) > 0.45 else "#FFFFFF"


def chip_colours(name: str, on: bool) -> tuple[str, str, str]:
    """``(background, text, frame)`` of a member chip: on, filled with the technique's colour;
    off, white with grey text and a grey frame (on/off never depends on the colour alone:
    the chip also says ``on`` / ``off``)."""
    if on:
        bg = technique_colour(name)
        return bg, text_on(bg), "#FFFFFF"
    return "#FFFFFF", "#6b6b6b", "#9a9a9a"
