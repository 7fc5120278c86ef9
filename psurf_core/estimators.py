"""Estimator specs: what ``--estimator`` accepts, parsed into techniques and a weighting.

Grammar (the CLI contract):

* ``reference`` - the volumetric path tracer (ground truth);
* a registered technique name, with ``-short`` where it has a short variant;
* ``mis:A+B+...`` (balance heuristic) / ``mis-power:A+B+...`` (power heuristic, beta = 2);
  a member ``A@0.25`` sweeps only that share of each pass's photons, and the heuristics
  use sample counts (``n_i Q_i``), which keeps the set unbiased;
* presets (``paper-single``, ``paper-multi``, ``paper-full``, ``fast-single``,
  ``fast-multi``, ``fast-full``) where registered in :data:`PRESETS`; ``fast-full@S`` puts
  its single-scattering set on the share ``S`` of the photons (:data:`SHARED_PRESETS`);
* ``SPEC~A~B``: ``SPEC`` (a preset or an MIS set) without its members ``A`` and ``B`` (what the
  window's member toggles give): every other member keeps what ``SPEC`` gave it (a preset's
  per-light choice, its MIS set), and a set left with one member is that technique alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .scene import Scene, SceneError
from .techniques import REGISTRY, Technique, UnknownTechnique, get_technique


@dataclass(frozen=True)
class Estimator:
    """A parsed estimator.

    Attributes
    ----------
    spec : str
        The text it was parsed from.
    groups : tuple of tuple of Technique
        Each group is estimated independently and summed; a group of two or more techniques
        is combined by MIS (``weighting``). A single technique is a group of one.
    weighting : str or None
        ``"balance"``, ``"power"`` or ``None`` (no MIS).
    reference : bool
        The path tracer rather than photon techniques.
    """

    spec: str
    groups: tuple = ()
    weighting: str | None = None
    reference: bool = False
    notes: tuple = field(default=())  # warnings for the user (dropped members, ...)
    #: Per group, the set it was made from (``SPEC~A``: ``SPEC``'s group, ``A`` included);
    #: empty: the groups themselves. The compiled MIS weights are built for these sets, so
    #: leaving members out compiles nothing new.
    full_groups: tuple = field(default=())

    @property
    def sets(self) -> tuple[tuple[tuple, tuple], ...]:
        """``(group, full_group)`` pairs (see :attr:`full_groups`)."""
        return tuple(zip(self.groups, self.full_groups or self.groups, strict=True))

    @property
    def techniques(self) -> tuple[Technique, ...]:
        return tuple(t for g in self.groups for t in g)

    @property
    def kernel(self) -> bool:
        return any(t.kernel_dim > 0 for t in self.techniques)


#: Preset name -> callable(spec, scene) -> Estimator (:func:`register_presets`).
PRESETS: dict = {}

#: Presets that take a share, ``NAME@S``: name -> callable(S) -> the builder of
#: :data:`PRESETS` with that share (``fast-full@S``: its single-scattering set on ``S``).
SHARED_PRESETS: dict = {}


def estimator_help() -> str:
    """One line per estimator name, for ``--help``."""
    lines = ["reference: volumetric path tracer, NEE + emitter hits + equiangular by MIS, "
             "guided (ground truth)"]
    for name, e in REGISTRY.items():
        suffix = " [-short]" if e.has_short else ""
        lines.append(f"{name}{suffix}: {e.summary}")
    for name in PRESETS:
        lines.append(f"{name}: preset (see README)")
    lines.append("mis:A+B+... / mis-power:A+B+...: MIS of photon-surface techniques "
                 "(A@0.25: A sweeps a quarter of the photons)")
    lines.append("fast-full@S: fast-full with its single-scattering set on a share S of "
                 "the photons")
    lines.append("SPEC~A~B: SPEC (a preset or an MIS set) without its members A and B")
    return "\n".join(lines)


def parse_estimator(spec: str, scene: Scene | None = None) -> Estimator:
    """Parse an estimator spec; with a ``scene``, check that it applies to some light.

    Raises
    ------
    UnknownTechnique
        For names that are not registered or misuse ``-short``.
    SceneError
        When no technique of the spec applies to any light of ``scene``.
    """
    spec = spec.strip()
    if spec == "reference":
        return Estimator(spec, reference=True)
    est = _parse(spec, scene)
    if scene is not None:
        est = replace(est, notes=est.notes + coverage_notes(est, scene))
    return est


def coverage_notes(est: Estimator, scene: Scene) -> tuple[str, ...]:
    """What part of ``scene``'s image ``est`` does not estimate (lights, scatter counts)."""
    notes = []
    techs = est.techniques
    for i, lt in enumerate(scene.lights):
        if not any(t.applies_to(lt) for t in techs):
            notes.append(f"light {i} ({lt.kind}) is not estimated by '{est.spec}'")
    lo, hi = scene.min_scatter, scene.max_scatter
    k_min = min(t.min_k for t in techs)
    caps = [t.max_k for t in techs]
    k_max = None if any(c is None for c in caps) else max(caps)
    if k_min > lo:
        missing = f"count {lo} is" if lo == k_min - 1 else f"counts {lo}..{k_min - 1} are"
        notes.append(f"scatter {missing} not estimated by '{est.spec}' "
                     f"(it produces K >= {k_min}); the image holds K >= {k_min} only")
    if k_max is not None and (hi < 0 or hi > k_max):
        notes.append(f"scatter counts above {k_max} are not estimated by '{est.spec}'")
    return tuple(notes)


def _parse(spec: str, scene: Scene | None) -> Estimator:
    if "~" in spec:
        return _without(spec, scene)
    if spec in PRESETS:
        return PRESETS[spec](spec, scene)
    if spec.endswith("-short") and spec[: -len("-short")] in PRESETS:
        raise UnknownTechnique(f"preset '{spec[:-6]}' has no short variant")
    if spec.startswith(("mis:", "mis-power:")):
        return parse_mis(spec, scene)
    head, at, _ = spec.partition("@")
    if at and head.strip() in SHARED_PRESETS:
        return SHARED_PRESETS[head.strip()](_split_share(spec)[1])(spec, scene)
    if at and head.strip() in PRESETS:
        raise UnknownTechnique(f"'{spec}': preset '{head.strip()}' takes no share (a share "
                               f"follows an MIS member or {', '.join(SHARED_PRESETS)})")
    tech = get_technique(spec)
    if scene is not None and not any(tech.applies_to(lt) for lt in scene.lights):
        kinds = sorted({lt.kind for lt in scene.lights})
        raise SceneError(
            f"{scene.path}: estimator '{spec}' applies to no light of this scene "
            f"(lights: {', '.join(kinds)})"
        )
    return Estimator(spec, groups=((tech,),))


def _without(spec: str, scene: Scene | None) -> Estimator:
    """``BASE~A~B``: the estimator ``BASE`` with members ``A``, ``B`` left out."""
    base_spec, *drop = (part.strip() for part in spec.split("~"))
    if not base_spec or any(not d for d in drop):
        raise UnknownTechnique(f"malformed spec '{spec}': expected SPEC~MEMBER~MEMBER...")
    if base_spec == "reference":
        raise UnknownTechnique(f"'{spec}': the path tracer has no members to leave out")
    base = _parse(base_spec, scene)
    names = [t.name for t in base.techniques]
    unknown = [d for d in drop if d not in names]
    if unknown:
        raise UnknownTechnique(f"'{spec}': '{unknown[0]}' is not a member of '{base_spec}' "
                               f"(members: {', '.join(names)})")
    kept = [(tuple(t for t in g if t.name not in drop), full) for g, full in base.sets]
    kept = [(g, full) for g, full in kept if g]
    if not kept:
        raise UnknownTechnique(f"'{spec}' leaves out every member of '{base_spec}'")
    return replace(base, spec=spec, groups=tuple(g for g, _ in kept),
                   full_groups=tuple(full for _, full in kept))


# ------------------------------------------------------------------------- MIS sets and presets
def _check_member(name: str) -> Technique:
    """The technique of MIS member ``name`` (``NAME`` or ``NAME@SHARE``, ``0 < SHARE <= 1``)."""
    name, share = _split_share(name)
    base = name[:-6] if name.endswith("-short") else name
    if base in PRESETS or name in PRESETS:
        raise UnknownTechnique(f"MIS member '{name}' is a preset; list techniques instead")
    tech = get_technique(name)
    entry = REGISTRY.get(base)
    if entry is not None and not entry.mis_ok:
        raise UnknownTechnique(f"MIS member '{name}' is a kernel baseline; MIS combines "
                               "unbiased photon-surface techniques only")
    tech.share = share
    return tech


def _split_share(member: str) -> tuple[str, float]:
    """``NAME@SHARE`` -> ``(NAME, SHARE)``; ``NAME`` -> ``(NAME, 1.0)``."""
    name, at, text = member.partition("@")
    if not at:
        return member, 1.0
    try:
        share = float(text)
    except ValueError:
        share = float("nan")
    if not 0.0 < share <= 1.0:
        raise UnknownTechnique(f"'{member}': the share after '@' must be a number in (0, 1], "
                               "the fraction of the photons it sweeps")
    return name.strip(), share


def _applicable(group, scene: Scene | None, spec: str):
    """Drop members that apply to no light of ``scene`` (with a warning)."""
    if scene is None:
        return group, ()
    kept, notes = [], []
    for t in group:
        if any(t.applies_to(lt) for lt in scene.lights):
            kept.append(t)
        elif not getattr(t, "per_light", False):  # a preset's per-light member: no note
            notes.append(f"MIS member '{t.name}' applies to no light of {scene.path}; dropped")
    if not kept:
        raise SceneError(f"{scene.path}: estimator '{spec}' has no member that applies to "
                         "a light of this scene")
    return kept, tuple(notes)


def parse_mis(spec: str, scene: Scene | None = None) -> Estimator:
    """Parse ``mis:A+B+...`` or ``mis-power:A+B+...``."""
    head, _, body = spec.partition(":")
    weighting = "power" if head == "mis-power" else "balance"
    names = [n.strip() for n in body.split("+")]
    if not body.strip() or any(not n for n in names):
        raise UnknownTechnique(f"malformed MIS spec '{spec}': expected {head}:A+B+...")
    if len({_split_share(n)[0] for n in names}) != len(names):
        raise UnknownTechnique(f"malformed MIS spec '{spec}': a member is listed twice")
    group = [_check_member(n) for n in names]
    group, notes = _applicable(group, scene, spec)
    return Estimator(spec, groups=(tuple(group),), weighting=weighting, notes=notes)


def _only(tech: Technique, kinds: tuple) -> Technique:
    """Restrict a technique instance to some light kinds (a preset's per-light choice)."""
    tech.lights = tuple(k for k in tech.lights if k in kinds)
    tech.per_light = True
    return tech


def _paper_single():
    return (*(get_technique(n) for n in ("ss-plane-uv", "ss-plane-ut", "ss-plane-vt")),
            get_technique("ss-cone"), get_technique("ss-sphere"),
            _only(get_technique("ss-disk"), ("point",)))


def _paper_multi():
    return tuple(get_technique(n) for n in
                 ("plane-t1t2", "plane-t1t3", "plane-t2t3", "cone", "cylinder"))


#: ``fast-single``'s shares of the single-scattering disk and sphere for area lights, where
#: the scene has no point (disk) or point / mesh (sphere) light that wants them on every
#: photon. Measured 2026-12-04 (docs/study.md, "Area lights at K = 1"): beside the three
#: planes they bring the relVar (the relMSE's noise part) to 0.25-0.34x the planes' alone at
#: equal CPU time on four area-light scenes, with the Var within 0.94-1.26x.
AREA_DISK_SHARE, AREA_SPHERE_SHARE = 0.45, 0.15

#: ``fast-full``'s share of the photons for each light kind's single-scattering members (a
#: point light's sphere, short cone and disk; a mesh light's sphere, cone and short disk; an
#: area light's whole set, its disk's and sphere's shares scaled alike), summed with the
#: multiple-scattering set that sweeps every photon. Sets of per-photon costs ``c_g`` and
#: relative variances ``v_g`` summed are best served by shares proportional to
#: ``sqrt(v_g / c_g)``; ``benchmarks/set_shares.py`` measured (2026-12-06, docs/vs_mitsuba.md,
#: "A share for single scattering in fast-full") 0.011 on ``dense_mesh_light`` and 0.15 on
#: ``mesh_light``, 0.087 on ``point`` and 0.015 on ``hg``, 0.26 on ``area``. The model is flat
#: about its optimum and a share above it risks less (a few split passes see a heavy tail's
#: variance low more often than high), so one share per kind, at or above the optima.
FULL_SINGLE_SHARES = {"mesh": 0.15, "point": 0.15, "area": 0.3}

ALL_KINDS = ("point", "area", "mesh")


def _fast_single(kinds=ALL_KINDS, shares: dict | None = None):
    """Single scattering tuned for equal time (docs/study.md, docs/vs_mitsuba.md), by light
    kind, for a scene whose lights are of ``kinds``; a point or a mesh light's members sweep
    ``shares[kind]`` of the photons (default all; ``fast-full``: :data:`FULL_SINGLE_SHARES`):

    * an area light: its three single-scattering planes (the two swept along the ray
      short), the disk on :data:`AREA_DISK_SHARE` and the sphere on
      :data:`AREA_SPHERE_SHARE` of the photons (the planes alone are heavy-tailed in the
      dim pixels that a relMSE weighs);
    * a mesh light: the sphere, cone and short disk (its triangles are small, so the planes
      built on them are tiny and rarely hit: on ``mesh_light`` ``fast-single`` had 6x
      ``paper-single``'s relMSE with the planes, 0.8x with these);
    * a point light: the sphere, short cone and disk.

    A technique is one member of the set, with one share: where lights of several kinds
    share the disk (point, area) or the sphere (all three), it sweeps the largest share any
    of them asks for.
    """
    point, area, mesh = ("point",), ("area",), ("mesh",)
    own = {"point": 1.0, "mesh": 1.0, "area": 1.0, **(shares or {})}

    def share(name, **wants):  # (a member none of whose kinds is here is dropped later)
        most = max((wants[k] for k in kinds if k in wants), default=1.0)
        return _check_member(f"{name}@{most:g}")

    return (*(_only(share(n, area=own["area"]), area) for n in (
                "ss-plane-uv", "ss-plane-ut-short", "ss-plane-vt-short")),
            _only(share("ss-sphere", point=own["point"], mesh=own["mesh"],
                        area=AREA_SPHERE_SHARE * own["area"]), point + mesh + area),
            _only(share("ss-cone-short", point=own["point"]), point),
            _only(share("ss-cone", mesh=own["mesh"]), mesh),
            _only(share("ss-disk", point=own["point"], area=AREA_DISK_SHARE * own["area"]),
                  point + area),
            _only(share("ss-disk-short", mesh=own["mesh"]), mesh))


#: ``fast-multi``'s strips (``plane-ut-short``, ``plane-vt-short``) for area lights: a strip
#: is kept whose typical normal (the light edge crossed with the light's normal: ``w_K`` is
#: cosine-distributed about it) faces the camera at least this share as well as the better
#: strip's (an edge-on strip costs hits and carries little weight).
STRIP_FACING = 0.5


def _strips(scene: Scene | None) -> tuple[str, ...]:
    """The light strips ``fast-multi`` sweeps for the area lights of ``scene`` (both without
    a scene): those facing the camera's forward direction (:data:`STRIP_FACING`)."""
    names = ("plane-ut-short", "plane-vt-short")
    areas = [] if scene is None else [lt for lt in scene.lights if lt.kind == "area"]
    if not areas:
        return names
    f = scene.camera.forward
    facing = np.zeros(2)
    for lt in areas:
        for i, edge in enumerate((lt.edge_u, lt.edge_v)):
            n = np.cross(edge, lt.normal)
            facing[i] = max(facing[i], abs(n @ f) / max(np.linalg.norm(n), 1e-300))
    return tuple(n for n, x in zip(names, facing, strict=True)
                 if x >= STRIP_FACING * facing.max())


def _fast_multi(kinds=ALL_KINDS, scene: Scene | None = None):
    """Multiple scattering tuned for equal time (docs/study.md, "Light strips"): photon
    planes (short ``plane-t1t2``) on every photon and the short cone on 20 % of them (MIS
    with sample counts); for an area light the light strips that face the camera
    (:func:`_strips`) on every photon, else the short ``plane-t2t3`` on 30 %."""
    members = [_check_member("planes")]
    rest = tuple(k for k in ("point", "mesh") if k in kinds)
    if "area" in kinds:
        members += [_only(_check_member(n), ("area",)) for n in _strips(scene)]
        if rest:
            members.append(_only(_check_member("plane-t2t3-short@0.3"), rest))
    else:
        members.append(_check_member("plane-t2t3-short@0.3"))
    return (*members, _check_member("cone-short@0.2"))


def _preset(groups_fn):
    """A preset whose groups ``groups_fn(kinds, scene)`` may depend on the kinds of the
    scene's lights (all kinds without a scene) and on the scene (None without one)."""
    def build(spec: str, scene: Scene | None) -> Estimator:
        groups, notes = [], []
        kinds = ALL_KINDS if scene is None else tuple(sorted({lt.kind for lt in scene.lights}))
        for g in groups_fn(kinds, scene):
            kept, n = _applicable(list(g), scene, spec) if scene is not None else (list(g), ())
            groups.append(tuple(kept))
            notes.extend(n)
        return Estimator(spec, groups=tuple(groups), weighting="balance", notes=tuple(notes))

    return build


def register_presets() -> None:
    """Install the presets: the paper's (``paper-*``: all long techniques, every member on
    every photon) and the ones tuned for equal time (``fast-*``: short members and sample
    counts where the study measured them to pay), all with the balance heuristic."""
    PRESETS["paper-single"] = _preset(lambda kinds, scene: [_paper_single()])
    PRESETS["paper-multi"] = _preset(lambda kinds, scene: [_paper_multi()])
    PRESETS["paper-full"] = _preset(lambda kinds, scene: [_paper_single(), _paper_multi()])
    PRESETS["fast-single"] = _preset(lambda kinds, scene: [_fast_single(kinds)])
    PRESETS["fast-multi"] = _preset(lambda kinds, scene: [_fast_multi(kinds, scene)])
    PRESETS["fast-full"] = _fast_full()
    SHARED_PRESETS["fast-full"] = _fast_full


def _fast_full(share: float | None = None):
    """``fast-full``: :func:`_fast_single` on :data:`FULL_SINGLE_SHARES` (``share``: that
    share for every light kind, an area light's disk and sphere scaled alike) summed with
    :func:`_fast_multi` on every photon."""
    shares = FULL_SINGLE_SHARES if share is None else dict.fromkeys(FULL_SINGLE_SHARES, share)
    return _preset(lambda kinds, scene: [_fast_single(kinds, shares), _fast_multi(kinds, scene)])


register_presets()
