"""psurf_core.kernels.numba_flags: the replaced methods give numba's own results."""

from numba.core.compiler import Flags

from psurf_core.kernels import jit  # noqa: F401 - installs the replacement
from psurf_core.kernels import numba_flags as nf


def _samples():
    a, b, c = Flags(), Flags(), Flags()
    b.nrt, b.error_model, b.inline = True, "numpy", "always"
    c.nrt, c.error_model, c.inline = True, "numpy", "always"
    d = Flags(c)
    d.fastmath = True
    e = Flags()
    e.nrt = Flags().nrt  # set explicitly to its default: equal to ``a``, another ``_values``
    return a, b, c, d, e


def test_installed_and_equal_to_numbas_methods():
    assert Flags.values is nf.values
    flags = _samples()
    for f in flags:
        assert nf.values(f) == nf.ORIGINAL["values"](f)
        assert hash(f) == nf.ORIGINAL["__hash__"](f)
        for g in flags:
            assert (f == g) == nf.ORIGINAL["__eq__"](f, g)
    a, b, c, d, e = flags
    assert b == c and a != b and c != d  # the sample has both outcomes
    assert a == e and a._values != e._values  # equal through the dicts, not the fast path
    assert nf.equal(a, 3) is NotImplemented
