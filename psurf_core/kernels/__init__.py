"""The compiled machinery (numba): how kernels are compiled and cached (:mod:`.jit`,
:mod:`.cache`), and the generic pieces every compiled technique shares.

This package knows no technique by name. A technique family declares, in its own module
under :mod:`psurf_core.techniques`, the records it uses and the compiled twins of its numpy
functions; the machinery here composes them.
"""
