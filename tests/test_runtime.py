"""The lazy Taichi runtime: starting it must not change the process's arithmetic."""

import subprocess
import sys


def test_starting_taichi_leaves_the_floating_point_environment_as_it_was():
    # ti.init sets flush-to-zero for the process; the runtime restores the caller's environment, so NumPy and
    # Python arithmetic (denormals) give the same results before and after a Taichi kernel
    code = ("import numpy as np; from workbench.kernels.runtime import ensure_taichi; "
            "from workbench_filters.tbd import tbd_weights; from workbench_filters.tbd.reference import kernel_inputs; "
            "ensure_taichi('cpu'); tbd_weights.tbd_log_weight_sums(*kernel_inputs(8, 3), backend='taichi'); "
            "print(repr(float((np.array([5e-324]) * 1.0)[0])), repr(5e-324 * 1.0))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["5e-324", "5e-324"]
