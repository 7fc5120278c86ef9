"""One home for tolerances and defaults (as trimesh keeps its epsilons in one module)."""

#: Offset (scene units) applied to the ends of a shadow segment so that the surface a vertex
#: sits on (an emitter, the box boundary) does not block it.
SHADOW_EPS = 1e-6

#: Tolerance of "inside the medium box" (scene units): vertices on the box boundary, and
#: rounding just beyond it, count as inside.
BOX_EPS = 1e-9

#: Padding of the blockers' bounding boxes (scene units) in the shadow tests' box reject.
BOUNDS_PAD = 1e-9

#: A ray-direction component below this is treated as parallel to a slab.
PARALLEL_EPS = 1e-12

#: |n . psi| below this (relative to |n|) marks a hit as near-singular in the inspector.
NEAR_SINGULAR = 1e-3

#: Below this |g| Henyey-Greenstein is sampled as isotropic (spec section 1).
HG_ISOTROPIC_G = 1e-3

#: Russian roulette (used only when max_scatter = -1) starts after this many scattering events.
ROULETTE_START = 8

#: Hard cap on traced scattering events when max_scatter = -1; with roulette the weight lost
#: beyond it is below 1e-6 of the total for albedo <= 0.95 (documented in trace.py).
MAX_TRACE_DEPTH = 64

#: Default memory budget (MiB) for chunked rays x primitives work.
DEFAULT_MEMORY_BUDGET_MIB = 512

#: Rough peak bytes per candidate ray-primitive pair in the numpy stages' intersect +
#: evaluate: the memory budget over this is a chunk's candidate pairs (``max_pairs``).
BYTES_PER_PAIR = 1200
