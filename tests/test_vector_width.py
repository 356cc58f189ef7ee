"""workbench.kernels.vector_width: the function it is called in vectorises with the CPU's full width, nothing else
changes (results, other functions)."""

import re

import numpy as np
import pytest

from workbench.kernels.backend import numba_available

pytestmark = pytest.mark.skipif(not numba_available(), reason="numba is not installed")


def _avx512() -> bool:
    import llvmlite.binding as llvm

    return bool(llvm.get_host_cpu_features().get("avx512f", False))


def _pair():
    import numba

    from workbench.kernels.vector_width import ATTRIBUTE, wide_vectors

    @numba.njit(inline="always")
    def body(x, out):
        for i in range(x.shape[0]):
            out[i] = x[i] * 1.5 + 0.25 * x[i] * x[i]

    # fresh compilations (not cached), whose assembly and LLVM IR can be read
    @numba.njit
    def plain(x, out):
        body(x, out)

    @numba.njit
    def marked(x, out):
        wide_vectors()
        body(x, out)

    return plain, marked, ATTRIBUTE


def test_the_attribute_marks_only_the_calling_function_and_changes_no_result():
    plain, marked, attribute = _pair()
    x = np.random.default_rng(0).normal(size=1001)
    a, b = np.empty_like(x), np.empty_like(x)
    plain(x, a)
    marked(x, b)
    np.testing.assert_array_equal(a, b)  # element-wise: bit for bit
    ir_marked = "\n".join(marked.inspect_llvm().values())
    ir_plain = "\n".join(plain.inspect_llvm().values())
    assert attribute in ir_marked and attribute not in ir_plain


@pytest.mark.skipif(not numba_available() or not _avx512(), reason="the CPU has no AVX-512")
def test_on_avx512_the_marked_loop_uses_512_bit_registers_and_the_plain_one_does_not():
    plain, marked, _ = _pair()
    x = np.ones(64)
    plain(x, np.empty_like(x))
    marked(x, np.empty_like(x))
    asm_marked = "\n".join(marked.inspect_asm().values())
    asm_plain = "\n".join(plain.inspect_asm().values())
    assert re.search(r"%zmm\d+", asm_marked)
    assert not re.search(r"%zmm\d+", asm_plain)  # LLVM's tuning for this CPU: 256-bit vectors
