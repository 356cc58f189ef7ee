"""The ``report`` benchmark group: the whole report of every installed paper, its wall time and peak memory.

``workbench report --full`` (``--quick`` in a quick bench) runs in a child process into a temporary folder, without
a cache, with the report's default worker processes (``--jobs``: the usable cores, at most 8); the peak resident set
size is that child's own (``VmHWM``, which the child prints as it ends; see :data:`_WRAP`) and, beside it, the
largest peak any of its worker processes reported (their own ``VmHWM``,
:attr:`workbench.report.engine.LocalProcesses.largest_worker_kib`).  Target: the report process's peak plus the
largest worker's peak times the number of workers (a bound on what they hold at once) at most 1.5 GiB at full size.

It also prints where the time went: the report's top tasks by share (:func:`top_tasks`, read from the report's
``summary.json``: each paper's time table, :func:`workbench.report.engine.task_time_table`), every task of every
paper (reported seed, unknowns' grid points, confirmation seed) ranked by its seconds against the seconds all the
report's tasks spent.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from workbench import hookimpl
from workbench.specs import BenchmarkSpec

#: Peak memory target of the full report of all papers (GiB).
PEAK_TARGET_GIB = 1.5
#: Wall-time target of the main job, ``workbench report`` at its default (full) size with firm verdicts, on two
#: cores from an empty folder (seconds).
WALL_TARGET_S = 300.0
#: The limit the full report (with the declared unknowns' grids and the confirmation seed) stays under on two cores
#: (seconds): ten minutes.
WALL_LIMIT_S = 600.0
#: How many of the report's tasks the benchmark prints, the largest share first.
TOP_TASKS = 10


def top_tasks(summary: dict, n: int = TOP_TASKS) -> dict:
    """The report's ``n`` largest tasks by share of the seconds all its tasks spent, from its ``summary.json``.

    Returns ``{"task_seconds": total, "tasks": count, "top": {"1": "paper 001 variants/0: 220.3 s, 13.30 %
    (runs 100, computed)", ...}}``; a cached or reused task counts 0 s, and the shares over every task of the report
    sum to 100 %.
    """
    from workbench.report.engine import task_time_table

    entries = []
    for paper in summary.get("papers", []):
        if paper.get("from_saved"):
            continue
        for t in paper.get("tasks", []):
            entries.append({**t, "key": f"paper {paper.get('paper')} {t.get('key')}"})
    table = task_time_table(entries)
    top = {}
    for i, row in enumerate(table["rows"][:max(int(n), 0)]):
        runs = "" if row["runs"] is None else f"runs {row['runs']}, "
        top[str(i + 1)] = (f"{row['task']}: {row['seconds']:.1f} s, {row['share_percent']:.2f} % "
                           f"({runs}{row['status']})")
    return {"task_seconds": table["computed_seconds"], "tasks": len(table["rows"]), "top": top}

_MAIN = "import sys; from workbench.cli import main; sys.exit(main(sys.argv[1:]))"

#: Runs the code given as its first argument, then prints the process's own peak resident set size
#: (:func:`workbench.bench.own_peak_kib`: ``getrusage`` would also count the image the child was forked from).
_WRAP = """
import sys
code = sys.argv.pop(1)
status = 0
try:
    exec(compile(code, "<report>", "exec"), {"__name__": "__main__"})
except SystemExit as exc:
    status = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
finally:
    from workbench.bench import own_peak_kib
    from workbench.report.engine import LocalProcesses
    print("@@PEAK_KIB@@", int(own_peak_kib()), int(LocalProcesses.largest_worker_kib), file=sys.stderr, flush=True)
sys.exit(status)
"""


def bench(quick: bool = False) -> dict:
    size = "quick" if quick else "full"
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp, tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", _WRAP, _MAIN, "report", f"--{size}", "--out", tmp,
                               "--no-progress"], stdout=out, stderr=err)
        code = proc.returncode
        wall = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(errors="replace"), err.read().decode(errors="replace")
        try:
            times = top_tasks(json.loads(Path(tmp, "summary.json").read_text(encoding="utf-8")))
        except (OSError, ValueError) as exc:
            times = {"error": f"no summary.json to read the task times from: {exc}"}
    marks = [line.split() for line in stderr.splitlines() if line.startswith("@@PEAK_KIB@@")]
    peaks = [int(m[1]) for m in marks]
    worker_kib = int(marks[-1][2]) if marks and len(marks[-1]) > 2 else 0
    stderr = "\n".join(line for line in stderr.splitlines() if not line.startswith("@@PEAK_KIB@@"))
    if code != 0 or not peaks:
        tail = " | ".join((stderr or stdout).strip().splitlines()[-3:])
        raise RuntimeError(f"workbench report --{size} failed (exit {code}): {tail}")
    from workbench.cli import DEFAULT_JOBS_CAP
    from workbench.report.engine import usable_cores

    jobs = min(usable_cores(), DEFAULT_JOBS_CAP)
    main_gib, worker_gib = peaks[-1] / 1024.0 ** 2, worker_kib / 1024.0 ** 2
    peak_gib = main_gib + (jobs * worker_gib if jobs > 1 else 0.0)
    papers = [line.split(":")[0] for line in stdout.splitlines() if line.startswith("paper ")]
    return {"size": size, "papers": ", ".join(papers), "report_wall_s": wall, "report_jobs": jobs,
            "report_process_peak_rss_gib": main_gib, "report_largest_worker_peak_rss_gib": worker_gib,
            "report_peak_rss_gib": peak_gib,
            "report_task_seconds": times.get("task_seconds"), "report_tasks": times.get("tasks"),
            "top_tasks_by_share": times.get("top") or times.get("error"),
            "target_report_peak_memory_gib": f"<= {PEAK_TARGET_GIB:g}", "measured_report_peak_memory_gib": peak_gib,
            "met_report_peak_memory_gib": bool(peak_gib <= PEAK_TARGET_GIB),
            **({"target_report_wall_s": f"<= {WALL_TARGET_S:g}", "measured_report_wall_s": wall,
                "met_report_wall_s": bool(wall <= WALL_TARGET_S),
                "note_report_wall_s": (f"the main job (workbench report, full size: firm verdicts, the unknowns' grids "
                                       f"and the confirmation seed) from an empty folder, {jobs} worker "
                                       f"process{'es' if jobs > 1 else ''} on {os.cpu_count()} cores; the target is "
                                       f"for two cores"),
                "target_report_wall_limit_s": f"<= {WALL_LIMIT_S:g}", "measured_report_wall_limit_s": wall,
                "met_report_wall_limit_s": bool(wall <= WALL_LIMIT_S),
                "note_report_wall_limit_s": (f"the same run against the limit the full report stays under on two "
                                             f"cores (ten minutes), {jobs} worker process{'es' if jobs > 1 else ''} "
                                             f"on {os.cpu_count()} cores")} if size == "full" else {}),
            "note_report_peak_memory_gib": (f"workbench report --{size} of every installed paper in one child process, "
                                            f"no cache, {jobs} worker process{'es' if jobs > 1 else ''} "
                                            f"(--jobs default), {wall:.0f} s on {os.cpu_count()} cores (1-minute load "
                                            f"average {load_before:.1f} before); peak resident set size of that "
                                            f"process ({main_gib:.2f} GiB) plus {jobs} x the largest worker's "
                                            f"({worker_gib:.2f} GiB)")}


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("report", "the whole report of every installed paper: wall time and peak memory", bench)]
