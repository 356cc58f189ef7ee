"""workbench.kernels.vector_width: the function it is called in vectorises with the CPU's full width, nothing else
changes (results, other functions).

The tests check what the code guarantees, never the host's default tuning (which differs by CPU model: LLVM's
tuning for Intel's Skylake-SP avoids 512-bit vectors, its tuning for AMD Zen 4 does not):

- the attribute is in the marked function's IR only, and the results are bit-identical;
- compiled for one fixed, named target whose tuning prefers 256-bit vectors (``skylake-avx512``), whatever the host
  is, the Numba-produced IR of the marked loop uses 512-bit registers and that of the unmarked loop does not;
- on a host with AVX-512 (checked first), the marked loop's machine code uses 512-bit registers.
"""

import re

import numpy as np
import pytest

from workbench.kernels.backend import numba_available

pytestmark = pytest.mark.skipif(not numba_available(), reason="numba is not installed")

#: A named x86-64 target with AVX-512 whose LLVM tuning prefers 256-bit vectors ("prefer-256-bit").
TARGET_TRIPLE = "x86_64-unknown-linux-gnu"
TARGET_CPU = "skylake-avx512"
ZMM = re.compile(r"%zmm\d+")


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


@pytest.mark.skipif(not numba_available() or not _avx512(), reason="the host CPU has no AVX-512 (avx512f)")
def test_on_an_avx512_host_the_marked_loop_uses_512_bit_registers():
    _, marked, _ = _pair()
    x = np.ones(64)
    marked(x, np.empty_like(x))
    assert ZMM.search("\n".join(marked.inspect_asm().values()))
    # no claim about the unmarked loop: whether LLVM's tuning for the host CPU uses zmm depends on the CPU model


def _named_target():
    """A target machine for ``TARGET_CPU``, or skip with the reason where this llvmlite cannot make one that
    emits 512-bit code."""
    import llvmlite.binding as llvm

    if not hasattr(llvm, "create_pass_builder"):  # llvmlite < 0.44: only the legacy pass manager
        pytest.skip("this llvmlite has no new pass manager (create_pass_builder) to optimise for a named target")
    try:
        llvm.initialize_all_targets()
        llvm.initialize_all_asmprinters()
        tm = llvm.Target.from_triple(TARGET_TRIPLE).create_target_machine(cpu=TARGET_CPU, features="", opt=3)
    except (RuntimeError, AttributeError) as exc:  # an llvmlite built without the X86 target
        pytest.skip(f"this llvmlite cannot make an x86-64 target machine for {TARGET_CPU!r}: {exc}")
    # the capability: an explicit 8-double vector add must come out in a zmm register on that target
    probe = llvm.parse_assembly("define <8 x double> @probe(<8 x double> %v) {\n"
                                "  %w = fadd <8 x double> %v, %v\n  ret <8 x double> %w\n}\n")
    probe.triple, probe.data_layout = TARGET_TRIPLE, str(tm.target_data)
    if not ZMM.search(tm.emit_assembly(probe)):
        pytest.skip(f"this llvmlite's LLVM does not emit AVX-512 code for cpu={TARGET_CPU!r}")
    return tm


def _unoptimised_ir(monkeypatch, fn) -> str:
    """The LLVM IR Numba generates for ``fn`` (one float64 1-D signature) before any optimisation: the module
    that defines the compiled function itself, as handed to Numba's code library."""
    from numba.core import codegen

    if not hasattr(codegen.CPUCodeLibrary, "add_llvm_module"):
        pytest.skip("this Numba has no CPUCodeLibrary.add_llvm_module to read the unoptimised IR from")
    seen = []
    original = codegen.CPUCodeLibrary.add_llvm_module

    def record(self, ll_module):
        seen.append(str(ll_module))
        return original(self, ll_module)

    with monkeypatch.context() as patch:
        patch.setattr(codegen.CPUCodeLibrary, "add_llvm_module", record)
        x = np.ones(64)
        fn(x, np.empty_like(x))
    name = fn.overloads[fn.signatures[0]].fndesc.mangled_name
    defining = [text for text in seen if re.search(rf'define [^\n]*@"?{re.escape(name)}"?\(', text)]
    assert len(defining) == 1, f"expected one module defining {name}, found {len(defining)}"
    return defining[0]


def _assembly_for(tm, ir_text: str) -> str:
    """``ir_text`` optimised at O3 (loop and SLP vectorisers on) and compiled for the target machine ``tm``."""
    import llvmlite.binding as llvm

    module = llvm.parse_assembly(ir_text)
    module.triple, module.data_layout = TARGET_TRIPLE, str(tm.target_data)
    options = llvm.create_pipeline_tuning_options(speed_level=3)
    options.loop_vectorization = True
    options.slp_vectorization = True
    builder = llvm.create_pass_builder(tm, options)
    builder.getModulePassManager().run(module, builder)
    return str(tm.emit_assembly(module))


def test_for_a_named_avx512_target_that_prefers_256_bits_only_the_marked_loop_uses_512_bit_registers(monkeypatch):
    # the same check on every host (x86-64 with or without AVX-512, arm64): Numba's IR, compiled for skylake-avx512
    tm = _named_target()
    plain, marked, attribute = _pair()
    ir_plain, ir_marked = _unoptimised_ir(monkeypatch, plain), _unoptimised_ir(monkeypatch, marked)
    assert attribute in ir_marked and attribute not in ir_plain
    asm_plain, asm_marked = _assembly_for(tm, ir_plain), _assembly_for(tm, ir_marked)
    assert re.search(r"%ymm\d+", asm_plain)  # the plain loop is vectorised too, at 256 bits
    assert not ZMM.search(asm_plain)  # the target's tuning: 256-bit vectors
    assert ZMM.search(asm_marked)  # the attribute: the full 512 bits
