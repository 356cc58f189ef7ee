"""The layout rules of ``docs/architecture.md``, checked on the source itself.

- nothing under ``workbench/`` imports a built-in plugin or names a particular paper;
- no plugin imports another plugin (a paper package imports only its own modules and the core);
- every built-in component declares its parameters, and every sensor and clutter generator its frame.
"""

import ast
import re
from pathlib import Path

import pytest

from workbench.frames import FRAMES
from workbench.plugins import load_host

ROOT = Path(__file__).parents[1]
PLUGIN_PACKAGES = {"workbench_filters": "filters", "workbench_sensors": "sensors", "workbench_clutter": "clutter",
                   "workbench_papers": "papers", "workbench_interop": "interop"}
PAPER_NAME = re.compile(r"paper[ _-]?00\d|method[ -]?[ABC]\b", re.IGNORECASE)


def _imports(path: Path) -> list[tuple[str, int]]:
    """Every absolute module an import statement of ``path`` names, with its line."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.module, node.lineno))
    return out


def _sources(folder: Path):
    return sorted(p for p in folder.rglob("*.py") if "tests" not in p.parts)


def test_the_core_imports_no_plugin():
    for path in _sources(ROOT / "workbench"):
        for module, line in _imports(path):
            assert module.split(".")[0] not in PLUGIN_PACKAGES, f"{path.relative_to(ROOT)}:{line} imports {module}"


def test_the_core_names_no_paper():
    for path in _sources(ROOT / "workbench"):
        if path.parts[-2] == "report" or path.name == "criteria.py":
            continue  # the report engine speaks of "papers" in general (recipes), never of one
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            assert not PAPER_NAME.search(line), f"{path.relative_to(ROOT)}:{i} names a paper: {line.strip()}"


def test_no_plugin_imports_another():
    for package, folder in PLUGIN_PACKAGES.items():
        for path in _sources(ROOT / "plugins" / folder):
            rel = path.relative_to(ROOT / "plugins" / folder)
            own = f"{package}.{rel.parts[0]}" if package == "workbench_papers" and len(rel.parts) > 1 else None
            for module, line in _imports(path):
                top = module.split(".")[0]
                if top in PLUGIN_PACKAGES:
                    assert own is not None and module.startswith(own), \
                        f"plugins/{folder}/{rel}:{line} imports another plugin's module {module}"


def test_a_deliberate_violation_is_caught(tmp_path):
    # the checks above are not vacuous: a module importing a plugin is found by the same parser
    bad = tmp_path / "bad.py"
    bad.write_text("from workbench_filters.kalman import KF\nimport workbench_papers.paper003.recipe\n")
    assert [m for m, _ in _imports(bad)] == ["workbench_filters.kalman", "workbench_papers.paper003.recipe"]
    assert PAPER_NAME.search("as in paper 003") and PAPER_NAME.search("method C") and not PAPER_NAME.search("papers")


@pytest.mark.parametrize("kind", ["workbench_filters", "workbench_sensors", "workbench_clutter_generators",
                                  "workbench_clutter_removers"])
def test_every_builtin_component_declares_its_parameters(kind):
    host = load_host()
    for name, spec in host.components[kind].items():
        if host.plugin_of(kind, name).distribution != "workbench":
            continue
        if spec.params:
            assert spec.parameters, f"{name} holds parameters but declares none"
        for p in spec.parameters:
            assert p.doc and p.doc != "(not declared by the plugin)", (name, p.name)


def test_every_builtin_sensor_and_clutter_generator_declares_a_known_frame():
    host = load_host()
    for kind in ("workbench_sensors", "workbench_clutter_generators"):
        for name, spec in host.components[kind].items():
            assert spec.detection_frame() in FRAMES, (name, spec.detection_frame())


#: Where compiled kernels live: the shared ones in the core, a plugin's own beside it in its package.
KERNEL_FOLDERS = ("workbench/kernels", "plugins/filters/crpf", "plugins/filters/tbd", "plugins/filters/sigma_point")


def _kernel_graph() -> dict[str, set[str]]:
    """``folder/module`` -> the kernel modules it imports (relative imports within its folder, and absolute imports
    of ``workbench.kernels.*`` from a plugin's kernels), at module level or inside a function."""
    graph = {}
    for folder in KERNEL_FOLDERS:
        for path in (ROOT / folder).glob("*.py"):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            edges = set()
            for node in ast.walk(tree):
                if not isinstance(node, ast.ImportFrom):
                    continue
                if node.level == 1:
                    names = [node.module.split(".")[0]] if node.module else [a.name for a in node.names]
                    edges |= {f"{folder}/{n}" for n in names if (ROOT / folder / f"{n}.py").is_file()}
                elif node.level == 0 and node.module and node.module.startswith("workbench.kernels."):
                    edges.add("workbench/kernels/" + node.module.split(".")[2])
            graph[f"{folder}/{path.stem}"] = edges
    return graph


def test_the_kernel_modules_import_each_other_without_cycles():
    # every import between kernel modules, at module level or inside a function, follows one direction:
    # dispatchers -> backends (numba, taichi) -> the NumPy twins and constants; a plugin's kernels -> the core's
    graph = _kernel_graph()
    state: dict[str, int] = {}

    def visit(node, trail):
        if state.get(node) == 1:
            raise AssertionError("import cycle among the kernels: " + " -> ".join(trail + [node]))
        if state.get(node) == 2:
            return
        state[node] = 1
        for nxt in graph.get(node, ()):
            visit(nxt, trail + [node])
        state[node] = 2

    for module in graph:
        visit(module, [])
    assert {"plugins/filters/tbd/tbd_weights_numba", "plugins/filters/crpf/crpf_numba",
            "workbench/kernels/counter_normals_numba"} <= set(graph)
    assert "workbench/kernels/particle_numba" in graph["plugins/filters/crpf/crpf_numba"]
