"""One kernel-backend policy (workbench.kernels.backend): the only list of arch names, the only place that decides
between compiled and NumPy code, and what it decided recorded where a module may fall back.

The source-tree scan reads the Python files of workbench/, plugins/ and scripts/ (tests excepted) with ``ast`` and
refuses (1) a literal tuple, list, set or dict that names two or more arches anywhere but backend.py, (2) a call of
``numba_available()`` (asking what is installed instead of what to run) and (3) ``import numba`` / ``import taichi``
anywhere but the policy, the Taichi runtime and the compiled twins (``*_numba.py``, ``*_taichi.py`` and the Numba
intrinsics they share); benchmarks, which time each installed backend by name, are listed with their reason.
"""

from __future__ import annotations

import argparse
import ast
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.kernels import backend
from workbench.kernels import counter_normals as cn

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("workbench", "plugins", "scripts")
POLICY = Path("workbench/kernels/backend.py")
#: May import Numba or Taichi: the policy, the Taichi runtime and the Numba intrinsics the compiled twins share
#: (every ``*_numba.py`` / ``*_taichi.py`` twin may too: a dispatcher imports one only after asking the policy).
IMPORTERS = {POLICY, Path("workbench/kernels/runtime.py"), Path("workbench/kernels/vector_width.py")}
#: Benchmarks time every installed backend by name and read the compiled code's own settings, so they ask what is
#: installed (never which code a filter runs): the only modules allowed to, each with what it does.
BENCHMARKS = {
    Path("plugins/filters/benchmarks.py"): "the compiled-draws floor is timed where Numba is installed",
    Path("plugins/filters/tbd/bench.py"): "the peak rate of a Numba FMA loop (the limit); the weight kernel per backend",
    Path("plugins/filters/crpf/bench.py"): "times the CRPF step on one Numba thread (numba.set_num_threads)",
    Path("scripts/gpu_check_compare.py"): "times the Taichi method-C kernel alone on arrays already on the device",
}


@pytest.fixture(autouse=True)
def _policy_default():
    """Each test starts from the policy's own choice, whatever WORKBENCH_BACKEND the suite runs under."""
    with backend.preferring("auto"):
        yield


def _docstring_nodes(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def _may_break(source: str) -> bool:
    """Whether the text could break a rule at all (a sound filter: every breach quotes two arch names or names
    numba or taichi), so that only those files are parsed."""
    quoted = sum(f'"{a}"' in source or f"'{a}'" in source for a in backend.ARCHES)
    return quoted >= 2 or "numba" in source or "taichi" in source


def violations(rel: Path, source: str) -> list[str]:
    """The policy's rules broken by one source file (``rel``: its path from the repository root)."""
    if not _may_break(source):
        return []
    tree = ast.parse(source, str(rel))
    arches = set(backend.ARCHES)
    docstrings = _docstring_nodes(tree)
    twin = rel.name.endswith(("_numba.py", "_taichi.py"))
    found = []
    for node in ast.walk(tree):
        where = f"{rel}:{getattr(node, 'lineno', 0)}"
        if rel != POLICY and isinstance(node, (ast.Tuple, ast.List, ast.Set, ast.Dict)):
            items = node.keys if isinstance(node, ast.Dict) else node.elts
            named = {e.value for e in items if isinstance(e, ast.Constant) and id(e) not in docstrings
                     and isinstance(e.value, str) and e.value in arches}
            if len(named) >= 2:
                found.append(f"{where}: a list of arch names {sorted(named)} (read workbench.kernels.backend.ARCHES)")
        if rel != POLICY and rel not in BENCHMARKS and isinstance(node, ast.Call):
            fn = node.func
            name = fn.id if isinstance(fn, ast.Name) else fn.attr if isinstance(fn, ast.Attribute) else ""
            if name == "numba_available":
                found.append(f"{where}: numba_available() chooses a path without the policy (ask backend.resolve "
                             f"or backend.runs_numba)")
        if isinstance(node, (ast.Import, ast.ImportFrom)) and not twin and rel not in IMPORTERS | set(BENCHMARKS):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            for mod in names:
                if mod.split(".")[0] in ("numba", "taichi"):
                    found.append(f"{where}: imports {mod} outside the policy and the compiled twins")
    return found


def _sources():
    for top in SCANNED:
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if "tests" in rel.parts or ".venv" in rel.parts or "__pycache__" in rel.parts:
                continue
            yield rel, path.read_text(encoding="utf-8")


def test_the_source_tree_keeps_to_the_one_policy():
    found = [v for rel, text in _sources() for v in violations(rel, text)]
    assert not found, "\n".join(found)
    assert all((ROOT / p).is_file() for p in BENCHMARKS)  # a stale allowance is removed, not kept


@pytest.mark.parametrize("added, rule", [
    ('ARCHES = ("cpu", "cuda", "vulkan")\n', "list of arch names"),
    ('CHOICES = ["cuda", "auto"]\n', "list of arch names"),
    ('TI = {"cuda": 1, "vulkan": 2}\n', "list of arch names"),
    ("from workbench.kernels.backend import numba_available\nFAST = numba_available()\n", "numba_available()"),
    ("from workbench.kernels import backend\nFAST = backend.numba_available()\n", "numba_available()"),
    ("import numba\n", "imports numba"),
    ("from taichi import lang\n", "imports taichi"),
])
def test_the_scan_catches_a_deliberately_added_breach(added, rule):
    rel = Path("plugins/filters/sigma_point/sigma_numba.py") if "taichi" in rule or "numba" in rule else None
    clean = (ROOT / "plugins/filters/sigma_point/__init__.py").read_text(encoding="utf-8")
    assert violations(Path("plugins/filters/sigma_point/__init__.py"), clean) == []
    got = violations(Path("plugins/filters/sigma_point/__init__.py"), clean + added)
    assert len(got) == 1 and rule in got[0], got
    if rel is not None and rule.startswith("imports"):  # a compiled twin may import its compiler
        assert violations(rel, added) == []
    # docstrings that name arches are prose, not lists
    assert violations(Path("x.py"), '"""Runs on ("cuda", "vulkan")."""\n') == []


def test_every_arch_list_is_the_policy_list():
    from workbench.cli import build_parser
    from workbench.kernels import runtime

    assert runtime.ARCHES is backend.ARCHES
    assert backend.ARCHES == backend.RUN_ARCHES + ("auto",) and backend.RUN_ARCHES == ("cpu",) + backend.GPU_ARCHES
    parser = build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    choices = {name: next(a.choices for a in sub._actions if a.dest == "arch")
               for name, sub in subparsers.choices.items() if name in ("report", "bench")}
    assert choices == {"report": list(backend.ARCHES), "bench": list(backend.RUN_ARCHES)}
    with pytest.raises(ValueError, match="unknown kernel arch 'tpu'"):
        backend.resolve("auto", "tpu")


def test_a_preference_makes_the_auto_choice():
    assert backend.default_backend() == "auto"  # the fixture's
    with backend.preferring("numpy"):
        assert backend.resolve("auto", "cpu") == "numpy" and backend.resolve("auto", "cuda") == "numpy"
        assert not backend.runs_numba()
        # a backend a caller names is honoured as given
        assert backend.resolve("taichi", "cpu") == "taichi"
        if backend.numba_available():
            assert backend.resolve("numba", "cpu") == "numba"
    assert backend.default_backend() == "auto"
    if backend.numba_available():
        with backend.preferring("numba"), pytest.raises(ValueError, match="'numba' .*runs on the CPU only"):
            backend.resolve("auto", "cuda")
    with pytest.raises(ValueError, match="unknown kernel backend 'fortran'"), backend.preferring("fortran"):
        pass


def _fresh(code: str, value: str) -> subprocess.CompletedProcess:
    env = {**os.environ, backend.ENV: value}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)


def test_the_environment_makes_the_auto_choice_for_a_process():
    code = ("from workbench.kernels import backend, counter_normals as cn; cn.counter_normals(5, 2, 3); "
            "print(backend.resolve(), cn.RECORD.last(), backend.resolve('taichi'))")
    out = _fresh(code, "numpy")
    assert out.returncode == 0 and out.stdout.split() == ["numpy", "numpy", "taichi"], out.stderr
    out = _fresh(code, "")  # empty: unset
    assert out.returncode == 0 and out.stdout.split()[0] == ("numba" if backend.numba_available() else "taichi")
    out = _fresh("from workbench.kernels import backend; backend.resolve()", "fortran")
    assert out.returncode != 0
    assert f"environment variable {backend.ENV}='fortran' is not a kernel backend" in out.stderr.splitlines()[-1]


def test_counter_normals_record_the_backend_that_ran():
    want = cn.counter_normals_numpy(7, 3, 11)
    got = cn.counter_normals(7, 3, 11, backend="numpy")
    assert cn.RECORD.last() == "numpy" and np.array_equal(got, want)
    if backend.numba_available():
        got = cn.counter_normals(7, 3, 11)
        assert cn.RECORD.last() == "numba" and np.array_equal(got, want)
        # normals are made on the host, so a kernel on a GPU arch still gets the compiled ones
        with backend.using("cuda"):
            cn.counter_normals(7, 3, 11)
        assert cn.RECORD.last() == "numba"
    with backend.preferring("numpy"):
        got = cn.counter_normals(7, 3, 11)
    assert cn.RECORD.last() == "numpy" and np.array_equal(got, want)
    if not backend.numba_available():
        with pytest.raises(ValueError, match="needs numba"):
            cn.counter_normals(7, 3, 11, backend="numba")


def _ukf_run(spec, B=3, steps=6):
    from workbench.filtering import run_filter
    from workbench.models import constant_velocity, range_bearing
    from workbench.rng import generator
    from workbench.trajectory import sample_motion
    from workbench.types import Gaussian, Scans

    rng = generator(3, "backend-policy")
    motion, model = constant_velocity(2, 1.0, 0.5), range_bearing(1.0, 0.01, sensor=(0.0, 0.0))
    truth = sample_motion(np.tile([200.0, 100.0, -2.0, 1.0], (B, 1)), motion, steps, rng)
    z = model.h(truth.states) + rng.standard_normal((B, steps, 2)) * np.array([1.0, 0.01])
    scans = Scans(z[:, :, None, :], np.ones((B, steps, 1), dtype=bool), np.arange(steps, dtype=float))
    prior = Gaussian.broadcast([205.0, 95.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), B)
    return run_filter(spec, prior, motion, model, scans, None)


def test_the_ukf_asks_the_policy_and_records_it():
    from workbench.plugins import load_host
    from workbench_filters import sigma_point

    spec = load_host().filter("ukf")
    runs = {}
    for forced in (None, "numpy"):
        before = sigma_point.backend_counts()
        with backend.preferring(forced or "auto"):
            runs[forced] = _ukf_run(spec)
        after = sigma_point.backend_counts()
        ran = {k: after.get(k, 0) - before.get(k, 0) for k in set(after) | set(before)}
        expect = "numba" if forced is None and backend.numba_available() else "numpy"
        assert ran.get(expect, 0) >= 11 and sum(ran.values()) == ran[expect], ran  # every call, by the policy
    with backend.using("vulkan"):  # off the CPU the policy has no Numba: the NumPy code, recorded
        _ukf_run(spec)
        assert sigma_point.last_backend() == "numpy"
    np.testing.assert_allclose(runs[None].mean, runs["numpy"].mean, rtol=1e-10, atol=1e-8)


def test_the_crpf_backend_argument_reaches_its_normals():
    """crpf(backend="numpy") on a model without the fused kernel: the propagation normals come from the NumPy
    twin too (the same numbers as the compiled ones)."""
    from workbench.filtering import run_filter
    from workbench.models import constant_velocity, linear_measurement
    from workbench.rng import generator
    from workbench.trajectory import sample_motion
    from workbench.types import Gaussian, Scans
    from workbench_filters.crpf import make_crpf

    rng = generator(4, "backend-policy")
    motion, model = constant_velocity(2, 1.0, 0.5), linear_measurement(np.eye(2, 4), np.eye(2))
    truth = sample_motion(np.tile([0.0, 0.0, 1.0, 1.0], (2, 1)), motion, 4, rng)
    z = model.h(truth.states) + rng.standard_normal((2, 4, 2))
    scans = Scans(z[:, :, None, :], np.ones((2, 4, 1), dtype=bool), np.arange(4, dtype=float))
    prior = Gaussian.broadcast([0.0, 0.0, 1.0, 1.0], np.diag([4.0, 4.0, 1.0, 1.0]), 2)
    out = {}
    for which in ("numpy", "auto"):
        spec = make_crpf(particles=20, cost="norm", backend=which)
        before = cn.RECORD.counts()
        out[which] = run_filter(spec, prior, motion, model, scans, generator(5, "crpf"))
        after = cn.RECORD.counts()
        ran = {k: after.get(k, 0) - before.get(k, 0) for k in set(after) | set(before)}
        expect = "numba" if which == "auto" and backend.numba_available() else "numpy"
        assert {k: v for k, v in ran.items() if v} == {expect: 3}, ran  # the three propagations
    np.testing.assert_array_equal(out["numpy"].mean, out["auto"].mean)


@pytest.mark.skipif(not backend.numba_available(), reason="Numba is not installed")
def test_threaded_asks_for_items_and_more_than_one_thread():
    import numba

    saved = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert not backend.threaded(10 ** 9, 16)  # one thread: never the threaded compilation
        if numba.config.NUMBA_NUM_THREADS > 1:
            numba.set_num_threads(2)
            assert backend.threaded(16, 16) and not backend.threaded(15, 16)
    finally:
        numba.set_num_threads(saved)
