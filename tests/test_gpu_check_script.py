"""scripts/gpu-check.sh without a GPU: its arguments, the commands of its dry run, the test selection they name, and
its compare and summary steps on hand-made report folders.  The whole script is not run here (minutes); it was run
by hand with ``--arch cpu`` (docs/benchmarks.md, "Checking the kernels on a GPU")."""

import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "gpu-check.sh"
HELPER = ROOT / "scripts" / "gpu_check_compare.py"


def run_script(*args, env=None, cwd=None):
    environ = {k: v for k, v in os.environ.items() if k != "OUT"}
    environ.update(env or {})
    return subprocess.run(["bash", str(SCRIPT), *args], capture_output=True, text=True, env=environ, cwd=cwd,
                          timeout=60)


def dry_run(*args, **kw) -> dict:
    """The dry run's steps: name -> (command, log path)."""
    out = run_script(*args, "--dry-run", **kw)
    assert out.returncode == 0, out.stderr
    steps = {}
    for line in out.stdout.splitlines():
        if line.startswith("#") or line.startswith("summary:"):
            continue
        name, rest = line.split(": ", 1)
        command, log = rest.rsplit("  > ", 1)
        steps[name] = (command, log)
    return steps


def test_dry_run_on_cuda_names_each_arch_and_the_out_folder(tmp_path):
    out = tmp_path / "out"
    steps = dry_run("--arch", "cuda", "--out", str(out), "--work", str(tmp_path / "w"))
    assert list(steps) == ["tests", "kernels-cuda", "kernels-cpu", "report-cuda", "report-cpu", "compare"]
    for name, (command, log) in steps.items():
        assert log == f"{out}/{name}.log"
    assert "WORKBENCH_TEST_ARCH=cuda " in steps["tests"][0] and "taichi-cuda" in steps["tests"][0]
    for arch in ("cuda", "cpu"):
        kernels = steps[f"kernels-{arch}"][0]
        assert f"method-c --arch {arch} --json {tmp_path}/w/method-c-{arch}.json" in kernels
        assert f"bench --quick --only tbd-weights --arch {arch} " in kernels and f"crpf-step --arch {arch} " in kernels
        report = steps[f"report-{arch}"][0]
        assert f"report --paper 000 --quick --arch {arch} --out {tmp_path}/w/report-{arch} " in report
    compare = shlex.split(steps["compare"][0])
    assert compare[compare.index("compare") + 1:compare.index("compare") + 3] == [f"{tmp_path}/w/report-cuda",
                                                                                 f"{tmp_path}/w/report-cpu"]
    assert compare[compare.index("--rtol") + 1] == "1e-6"
    assert not out.exists()  # a dry run writes nothing


def test_dry_run_on_the_cpu_stand_in_runs_the_cpu_twice_and_full_size_changes_the_sizes(tmp_path):
    steps = dry_run("--arch", "cpu", "--out", str(tmp_path), "--size", "full", "--rtol", "1e-5")
    assert list(steps) == ["tests", "kernels-cpu", "report-cpu", "report-cpu-again", "compare"]
    assert "WORKBENCH_TEST_ARCH=cpu " in steps["tests"][0]
    assert "--quick" not in steps["kernels-cpu"][0] and "--arch cpu" in steps["kernels-cpu"][0]
    assert "--full --arch cpu" in steps["report-cpu"][0] and "--full --arch cpu" in steps["report-cpu-again"][0]
    assert "--rtol 1e-5" in steps["compare"][0]


def test_report_size_sets_the_reports_alone(tmp_path):
    steps = dry_run("--arch", "cuda", "--out", str(tmp_path), "--report-size", "full")
    assert "bench --quick " in steps["kernels-cuda"][0] and "bench --quick " in steps["kernels-cpu"][0]
    assert "--full --arch cuda" in steps["report-cuda"][0] and "--full --arch cpu" in steps["report-cpu"][0]
    steps = dry_run("--arch", "cuda", "--out", str(tmp_path), "--size", "full", "--report-size", "quick")
    assert "--quick" not in steps["kernels-cuda"][0] and "--quick --arch cuda" in steps["report-cuda"][0]


def test_out_folder_defaults_to_OUT_then_to_gpu_check_out_and_wheels_add_the_install(tmp_path):
    steps = dry_run("--arch", "cpu", env={"OUT": str(tmp_path / "device-out")})
    assert steps["tests"][1] == f"{tmp_path}/device-out/tests.log"
    steps = dry_run("--arch", "cpu", "--wheels", "whl", cwd=tmp_path)
    assert steps["tests"][1] == f"{tmp_path}/gpu-check-out/tests.log"  # relative to where it was called
    install = steps["install"][0]
    assert f"pip install --no-index --find-links {tmp_path}/whl taichi dill" in install
    assert "pip install --no-index --no-deps --no-build-isolation -e ." in install


@pytest.mark.parametrize("args, message", [
    (["--arch", "tpu"], "--arch must be cuda, vulkan or cpu, not 'tpu'"),
    (["--size", "huge"], "--size must be quick or full"),
    (["--report-size", "huge"], "--report-size must be quick or full, not 'huge'"),
    (["--deadline", "soon"], "--deadline must be a whole number"),
    (["--rtol", "tight"], "--rtol must be a number"),
    (["--frobnicate"], "unknown argument '--frobnicate'"),
    (["--out"], "--out needs a value"),
    (["--out", "--arch", "cpu"], "--out needs a value"),  # not a folder named --arch
])
def test_bad_arguments_get_one_line_and_exit_2(args, message):
    out = run_script("--dry-run", *args)  # never a real run, whatever the parsing does
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.strip().splitlines() == [f"gpu-check: error: {out.stderr.split('error: ', 1)[1].strip()}"]
    assert message in out.stderr


def test_the_tests_step_selects_the_twin_tests_on_the_arch(tmp_path):
    command = dry_run("--arch", "cpu", "--out", str(tmp_path))["tests"][0]
    words = shlex.split(command)
    selection = words[words.index("pytest") + 1:]
    # the step's own -q makes --collect-only list node ids
    got = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", *selection], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    ids = [line for line in got.stdout.splitlines() if "::" in line]
    twins = [i for i in ids if "on_test_arch" in i]
    # method C: {small, large-N, large-M} x {float64, float32}; CRPF: {small, large-N, large-B} x {previous, paper}
    assert len([i for i in twins if "method_c" in i]) == 6 and len([i for i in twins if "crpf" in i]) == 6
    assert any("[taichi-cpu" in i for i in ids)  # and the existing per-arch cases of that arch
    assert all("on_test_arch" in i or "taichi-cpu" in i for i in ids)


def make_report(folder: Path, scale: float = 1.0) -> Path:
    """A report folder as ``workbench report`` writes it, reduced to what compare_reports.py reads."""
    (folder / "paper000").mkdir(parents=True)
    summary = {"papers": [{"paper": "000", "tables": [
        {"id": "table3", "columns": ["filter", "RMSE (m)", "wall (s)"],
         "rows": [["tbd-pf", f"{41.25 * scale:.12g}", "3.1"], ["ekf", "57.5", "0.2"]]}]}]}
    (folder / "summary.json").write_text(json.dumps(summary))
    np.savez(folder / "paper000" / "fig8.npz", estimate_km=np.array([1.5, 2.25, 3.0]) * scale,
             time_s=np.array([0.1, 0.2, 0.3]) * (2.0 - scale))  # measured times: never compared
    return folder


def compare(a: Path, b: Path, tmp_path: Path, rtol="1e-6"):
    target = tmp_path / "compare.json"
    out = subprocess.run([sys.executable, str(HELPER), "compare", str(a), str(b), "--rtol", rtol, "--json",
                          str(target)], capture_output=True, text=True, timeout=60)
    return out.returncode, json.loads(target.read_text())


def test_compare_step_gives_agree_within_and_differ_beyond_the_tolerance(tmp_path):
    base = make_report(tmp_path / "a")
    code, verdict = compare(base, make_report(tmp_path / "same"), tmp_path)
    assert code == 0 and verdict["verdict"] == "agree" and verdict["rtol"] == 1e-6
    assert verdict["items"] == {"paper000 table table3": "identical", "paper000 figure fig8": "identical"}
    code, verdict = compare(base, make_report(tmp_path / "close", 1 + 1e-8), tmp_path)  # GPU-like round-off
    assert code == 0 and verdict["verdict"] == "agree"
    assert verdict["items"] == {"paper000 table table3": "agrees", "paper000 figure fig8": "agrees"}
    assert 0.5e-8 < verdict["max_relative_difference"] < 2e-8
    code, verdict = compare(base, make_report(tmp_path / "far", 1 + 1e-4), tmp_path)
    assert code == 1 and verdict["verdict"] == "differ"
    assert verdict["items"] == {"paper000 table table3": "differs", "paper000 figure fig8": "differs"}
    code, verdict = compare(base, make_report(tmp_path / "far2", 1 + 1e-4), tmp_path, rtol="1e-3")
    assert code == 0 and verdict["verdict"] == "agree"  # the tolerance is the one asked for
    code, verdict = compare(base, tmp_path / "no-such-report", tmp_path)
    assert code == 2 and verdict["verdict"] == "error" and "summary.json" in verdict["error"]


def test_summary_gathers_the_steps_and_fails_on_a_failed_step(tmp_path):
    out, work = tmp_path / "out", tmp_path / "work"
    out.mkdir()
    make_report(work / "report-cpu")
    make_report(work / "report-cpu-again")
    compare(work / "report-cpu", work / "report-cpu-again", work)
    (work / "bench-cpu.json").write_text(json.dumps({"groups": {"tbd-weights": {"kernel_arch": "cpu"}}}))
    (work / "method-c-cpu.json").write_text(json.dumps({"arch": "cpu", "rows": [{"N": 10, "M": 2}]}))
    times = {"computed_seconds": 12.5, "counts": {"computed": 2, "cached": 0},
             "rows": [{"task": "sweep", "runs": 20, "seconds": 10.0, "share_percent": 80.0, "status": "computed"},
                      {"task": "timing", "runs": 1, "seconds": 2.5, "share_percent": 20.0, "status": "computed"}]}
    (work / "report-cpu" / "paper000" / "outcome.json").write_text(
        json.dumps({"size": "full", "seconds": 33.0, "task_times": times, "criteria": []}))
    (out / "tests.log").write_text("....\n18 passed, 36 deselected, 1 warning in 30.52s\n")
    rows = [("tests", "ok", 0, 30.5), ("bench-cpu", "ok", 0, 120.0), ("report-cpu", "ok", 0, 40.0),
            ("report-cpu-again", "ok", 0, 41.0), ("compare", "ok", 0, 1.0)]

    def summary(rows):
        (work / "steps.tsv").write_text("".join(f"{n}\t{s}\t{c}\t{t}\tcmd {n}\n" for n, s, c, t in rows))
        code = subprocess.run([sys.executable, str(HELPER), "summary", "--out", str(out), "--work", str(work),
                               "--arch", "cpu", "--size", "quick", "--rtol", "1e-6"], timeout=60).returncode
        return code, json.loads((out / "gpu-check.json").read_text())

    code, got = summary(rows)
    assert code == 0 and got["ok"] and got["failed_steps"] == []
    assert [s["name"] for s in got["steps"]] == [r[0] for r in rows]
    assert got["steps"][0]["result"] == "18 passed, 36 deselected, 1 warning in 30.52s"
    assert got["steps"][1] == {"name": "bench-cpu", "status": "ok", "exit": 0, "seconds": 120.0,
                               "log": "bench-cpu.log", "command": "cmd bench-cpu"}
    assert got["compare"]["verdict"] == "agree" and got["bench"]["cpu"]["groups"]["tbd-weights"]["kernel_arch"] == "cpu"
    assert got["method_c"] == {"cpu": {"arch": "cpu", "rows": [{"N": 10, "M": 2}]}}
    assert got["reports"] == {"cpu": {"size": "full", "seconds": 33.0, "computed_task_seconds": 12.5,
                                      "counts": {"computed": 2, "cached": 0},
                                      "tasks": [{"task": "sweep", "runs": 20, "seconds": 10.0},
                                                {"task": "timing", "runs": 1, "seconds": 2.5}]}}
    rows[2] = ("report-cpu", "timed out", 124, 240.0)
    code, got = summary(rows)
    assert code == 1 and not got["ok"] and got["failed_steps"] == ["report-cpu"]


@pytest.mark.parametrize("preferred", [None, "taichi"])
def test_method_c_times_each_size_and_precision_and_compares_them(monkeypatch, preferred):
    """The method-C timing on the CPU arch at small sizes: a row per size, rates from the calls' own times, the
    float32 result within the float32 kernel's tolerance of the float64 one; under Taichi (as on a GPU) the call's
    parts too."""
    import contextlib

    from workbench.kernels.backend import preferring, runs_numba

    monkeypatch.syspath_prepend(str(HELPER.parent))
    import gpu_check_compare

    with preferring(preferred) if preferred else contextlib.nullcontext():
        got = gpu_check_compare.method_c("cpu", 1, sizes=((300, 7), (50, 40)))
        expected = "numba" if runs_numba() else "taichi"
    assert got["arch"] == "cpu" and got["repeat"] == 1 and got["backend"] == expected
    for row in got["rows"]:
        parts = {"float64_pack_seconds", "float64_kernel_seconds", "float64_kernel_pairs_per_s"}
        assert parts <= set(row) if expected == "taichi" else not parts & set(row)
        if expected == "taichi":
            assert row["float64_kernel_pairs_per_s"] == pytest.approx(row["N"] * row["M"]
                                                                      / row["float64_kernel_seconds"])
    assert [(r["N"], r["M"]) for r in got["rows"]] == [(300, 7), (50, 40)]
    for row in got["rows"]:
        for precision in ("float64", "float32"):
            assert row[f"{precision}_pairs_per_s"] == pytest.approx(row["N"] * row["M"] / row[f"{precision}_seconds"])
        assert row["float32_over_float64"] == pytest.approx(row["float32_pairs_per_s"] / row["float64_pairs_per_s"])
        assert 0 < row["max_abs_difference"] < 1e-3  # float32 arithmetic, not the same numbers, not far off
