"""``wide_vectors()``: let LLVM vectorise one compiled kernel with the CPU's full vector width.

LLVM tunes code for the Intel server CPUs since Skylake-SP to prefer 256-bit vectors even where AVX-512 is
there (on the first of them, 512-bit instructions lowered the clock of the whole core).  Numba compiles for the
host CPU with that tuning, so a loop vectorises to four doubles where the CPU takes eight.  Calling
:func:`wide_vectors` inside a Numba-compiled function marks the LLVM function it is compiled into with
``"prefer-vector-width"="512"``: the vectoriser then uses the full width in that function only (every other
Numba function of the process, the user's included, keeps LLVM's choice).  On a CPU without AVX-512 the
attribute changes nothing: the widest legal vector stays 256 bits.

Where to call it: in the body whose loops should vectorise; inside a ``prange`` loop for a ``parallel=True``
kernel (Numba outlines that body into a function of its own), and it then covers the serial compilation of the
same code too.  It changes no result bit of an element-wise loop; a reduction compiled with ``reassoc`` sums in
eight lanes instead of four (its last bits), which is why the kernels' twins are held to them with tolerances.

The attribute is a key-value string attribute, which llvmlite's ``FunctionAttributes`` does not list among the
names it accepts; it is added to the attribute set directly, and llvmlite writes it into the function's
definition as it is (``define ... "prefer-vector-width"="512"``), which LLVM parses.
"""

from __future__ import annotations

from numba import types
from numba.extending import intrinsic

__all__ = ["wide_vectors", "ATTRIBUTE"]

#: The LLVM function attribute :func:`wide_vectors` adds.
ATTRIBUTE = '"prefer-vector-width"="512"'


@intrinsic
def wide_vectors(typingctx):
    """Mark the function being compiled: ``"prefer-vector-width"="512"`` (see the module docstring)."""

    def codegen(context, builder, signature, args):
        # FunctionAttributes.add only accepts its fixed list of names; the set itself takes any attribute text
        set.add(builder.function.attributes, ATTRIBUTE)
        return context.get_dummy_value()

    return types.none(), codegen
