"""The ``report`` benchmark group: the whole report of every installed paper, its wall time and peak memory.

``workbench report --full`` (``--quick`` in a quick bench) runs in a child process into a temporary folder, without
a cache; the peak resident set size is that child's own (``ru_maxrss`` of ``os.wait4`` on it).  Target: at most 1.5 GiB at full size.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time

from workbench import hookimpl
from workbench.specs import BenchmarkSpec

#: Peak memory target of the full report of all papers (GiB).
PEAK_TARGET_GIB = 1.5

_MAIN = "import sys; from workbench.cli import main; sys.exit(main(sys.argv[1:]))"


def bench(quick: bool = False) -> dict:
    size = "quick" if quick else "full"
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp, tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", _MAIN, "report", f"--{size}", "--out", tmp, "--no-progress"],
                                stdout=out, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own resource usage, whatever ran before it
        proc.returncode = code = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    if code != 0:
        tail = " | ".join((stderr or stdout).strip().splitlines()[-3:])
        raise RuntimeError(f"workbench report --{size} failed (exit {code}): {tail}")
    peak_gib = usage.ru_maxrss / 1024.0 ** 2  # kB on Linux
    papers = [line.split(":")[0] for line in stdout.splitlines() if line.startswith("paper ")]
    return {"size": size, "papers": ", ".join(papers), "report_wall_s": wall, "report_peak_rss_gib": peak_gib,
            "target_report_peak_memory_gib": f"<= {PEAK_TARGET_GIB:g}", "measured_report_peak_memory_gib": peak_gib,
            "met_report_peak_memory_gib": bool(peak_gib <= PEAK_TARGET_GIB),
            "note_report_peak_memory_gib": (f"workbench report --{size} of every installed paper in one child process, "
                                            f"no cache, {wall:.0f} s on {os.cpu_count()} cores (1-minute load average "
                                            f"{load_before:.1f} before); peak resident set size of that process")}


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("report", "the whole report of every installed paper: wall time and peak memory", bench)]
