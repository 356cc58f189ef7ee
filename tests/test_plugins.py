import os
import subprocess
import sys
import textwrap
from importlib import metadata

import pytest

from fixtures import broken_plugins

from workbench.plugins import load_host, UnknownComponent


def test_builtins_load_through_entry_points():
    host = load_host()
    names = {p.name: p for p in host.plugins}
    assert names["kalman"].status == "ok" and names["kalman"].distribution == "workbench"
    assert {"kf", "ekf", "sir"} <= set(host.filters)
    assert host.plugin_of("workbench_filters", "kf").name == "kalman"


@pytest.mark.parametrize("name, obj, fragment", [
    ("teleport", broken_plugins.UNKNOWN_HOOK, "not a workbench hook"),
    ("raiser", broken_plugins.RAISES, "boom from a plugin"),
    ("wrongtype", broken_plugins.WRONG_TYPE, "expected FilterSpec"),
    ("typo", broken_plugins.MISSPELT_CAPABILITY, "unknown capabilities ['gausian'] (known: clutter_density, "),
    ("typo", broken_plugins.MISSPELT_CAPABILITY, "'gausian': did you mean 'gaussian'?"),
])
def test_broken_plugin_is_reported_and_the_rest_work(name, obj, fragment):
    host = load_host(extra_plugins=[(name, obj)])
    info = next(p for p in host.plugins if p.name == name)
    assert info.status == "broken"
    assert fragment in info.error and name in info.error
    assert host.filter("kf").summary.startswith("Kalman")  # the built-in is untouched


def test_a_third_party_component_reusing_a_builtin_name_is_refused_with_a_warning_and_the_rest_kept():
    # a plugin name that sorts before the built-in one must not take the name over or disable the built-in
    host = load_host(extra_plugins=[("aaa-impostor", broken_plugins.DUPLICATE_AND_OWN)])
    info = next(p for p in host.plugins if p.name == "aaa-impostor")
    assert info.status == "ok" and ("filter", "own-filter") in info.provides
    assert len(info.warnings) == 1
    assert "'kf'" in info.warnings[0] and "plugin 'kalman' (distribution workbench)" in info.warnings[0]
    assert "built-in names are reserved" in info.warnings[0]
    assert host.filter("kf").summary.startswith("Kalman")
    assert next(p for p in host.plugins if p.name == "kalman").status == "ok"
    assert host.warnings == info.warnings


def test_a_component_whose_defaults_fail_its_own_declarations_makes_its_plugin_broken():
    host = load_host(extra_plugins=[("baddecl", broken_plugins.BAD_DECLARATION)])
    info = next(p for p in host.plugins if p.name == "baddecl")
    assert info.status == "broken" and "not valid for its own declaration" in info.error and "particles" in info.error


def test_import_failure_is_reported_with_its_distribution():
    ep = metadata.EntryPoint("ghost", "no_such_module_xyz", "workbench")
    host = load_host(entry_points=list(metadata.entry_points(group="workbench")) + [ep])
    info = next(p for p in host.plugins if p.name == "ghost")
    assert info.status == "broken" and "ModuleNotFoundError" in info.error
    assert "kf" in host.filters


def test_block_by_argument_and_environment(monkeypatch):
    host = load_host(block=["particle"])
    assert next(p for p in host.plugins if p.name == "particle").status == "blocked"
    assert "sir" not in host.filters
    with pytest.raises(UnknownComponent, match="no filter named 'sir'.*particle \\(blocked\\)"):
        host.filter("sir")
    monkeypatch.setenv("WORKBENCH_BLOCK", "kalman, particle")
    host = load_host()
    assert "kf" not in host.filters and "sir" not in host.filters


def _fake_distribution(tmp_path, body):
    """A third-party distribution on disk: a module and its dist-info with a workbench entry point."""
    (tmp_path / "fake_plugin.py").write_text(textwrap.dedent(body))
    info = tmp_path / "fake_plugin-0.3.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-plugin\nVersion: 0.3\n")
    (info / "entry_points.txt").write_text("[workbench]\nfake = fake_plugin\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return env


def test_cli_lists_builtins_and_a_broken_third_party_plugin(tmp_path):
    env = _fake_distribution(tmp_path, "raise ImportError('missing dependency libfoo')\n")
    out = subprocess.run([sys.executable, "-m", "workbench.cli", "plugins"], env=env, capture_output=True,
                         text=True, check=True)
    assert "fake-plugin" in out.stdout and "broken" in out.stdout and "libfoo" in out.stdout
    assert "kf" in out.stdout and "ekf" in out.stdout
    assert "plugin fake (fake-plugin 0.3) is broken" in out.stderr


def test_cli_lists_a_working_third_party_filter(tmp_path):
    env = _fake_distribution(tmp_path, """
        from workbench import hookimpl
        from workbench.specs import FilterSpec
        @hookimpl
        def workbench_filters():
            return [FilterSpec("noop", "does nothing", lambda p, r: p, lambda s, m, r: s,
                               lambda s, sc, m, r: s, lambda s: s)]
    """)
    out = subprocess.run([sys.executable, "-m", "workbench.cli", "plugins"], env=env, capture_output=True,
                         text=True, check=True)
    line = next(l for l in out.stdout.splitlines() if " noop " in l)
    assert "fake-plugin" in line and "0.3" in line and line.rstrip().endswith("ok")


def test_example_plugin_once_installed_is_listed_and_joins_a_report(tmp_path):
    """The README's test command installs examples/workbench-alpha-beta like any third-party package."""
    try:
        metadata.distribution("workbench-alpha-beta")
    except metadata.PackageNotFoundError:
        pytest.skip("the example plugin is not installed (pip install ./examples/workbench-alpha-beta)")
    out = subprocess.run([sys.executable, "-m", "workbench.cli", "plugins"], capture_output=True, text=True,
                         check=True)
    line = next(l for l in out.stdout.splitlines() if " alpha-beta " in l)
    assert "workbench-alpha-beta" in line and line.rstrip().endswith("ok")
    from fixtures import demo_plugin

    from workbench.report.engine import run_report

    host = load_host(extra_plugins=[("demo", demo_plugin)])
    report = run_report(host, tmp_path, papers=["demo"], filters="+alpha-beta", progress=False)
    assert "alpha-beta" in report.papers[0].filters and not report.papers[0].errors


def test_find_takes_a_configured_filter_label_as_check_plugin_does():
    host = load_host()
    [(kind, spec)] = host.find("sir(particles=300)")
    assert kind == "filter" and spec.name == "sir(particles=300)" and spec.params["particles"] == 300
    assert host.find("no-such-component") == []


def test_a_name_of_another_kind_is_named_as_that_kind():
    host = load_host()
    with pytest.raises(UnknownComponent) as info:
        host.filter("range-bearing(sigma_theta=0.1)")
    assert str(info.value) == ("'range-bearing' is a sensor, not a filter (installed filters: "
                               + ", ".join(sorted(host.filters)) + ")")
    with pytest.raises(UnknownComponent, match="^'kf' is a filter, not a sensor"):
        host.sensor("kf")
    with pytest.raises(UnknownComponent, match="^no filter named 'nowhere' is installed"):
        host.filter("nowhere")


def test_a_plugin_names_what_it_cannot_provide_here_and_why():
    from types import SimpleNamespace

    from workbench.plugins import UNAVAILABLE_ATTRIBUTE

    optional = SimpleNamespace(**{UNAVAILABLE_ATTRIBUTE: {
        ("filter", "opt-kf"): "needs libopt: pip install libopt",
        ("filter", "kf"): "must not hide an installed filter",
        ("no such kind", "x"): "ignored"}})
    host = load_host(extra_plugins=[("optional", optional)])
    info = next(p for p in host.plugins if p.name == "optional")
    assert info.status == "ok" and info.provides == () and not info.warnings  # quiet until asked
    with pytest.raises(UnknownComponent, match=r"^the filter 'opt-kf' needs libopt: pip install libopt$"):
        host.filter("opt-kf")
    assert host.filter("kf").name == "kf"
    mine = lambda h: {k: v for k, v in h.unavailable.items() if k[1] in ("opt-kf", "kf", "x")}  # noqa: E731
    assert mine(host) == {("filter", "opt-kf"): "needs libopt: pip install libopt",
                          ("filter", "kf"): "must not hide an installed filter"}
    # a blocked plugin says nothing of what it would provide
    assert mine(load_host(block=["optional"], extra_plugins=[("optional", optional)])) == {}


def test_a_filter_serving_a_motion_model_no_plugin_provides_makes_its_plugin_broken():
    from dataclasses import replace
    from types import SimpleNamespace

    from workbench import hookimpl

    ukf = load_host().filter("ukf")
    served = SimpleNamespace(workbench_filters=hookimpl(lambda: [
        replace(ukf, name="ukf-turns", motion_models=("ct-rate",)),
        replace(ukf, name="ukf-warp", motion_models=("ct-rate", "warp-drive"))]))
    host = load_host(extra_plugins=[("served", served)])
    info = next(p for p in host.plugins if p.name == "served")
    assert info.status == "broken"
    assert ("filter 'ukf-warp' serves the motion model 'warp-drive', which no plugin provides (installed motion "
            "models: ca2d, ca3d, ct, ct-rate, ") in info.error
    assert "ukf-turns" not in host.filters and "ukf-warp" not in host.filters and "ukf" in host.filters
    fine = SimpleNamespace(workbench_filters=hookimpl(lambda: [replace(ukf, name="ukf-turns",
                                                                       motion_models=("ct-rate",))]))
    assert load_host(extra_plugins=[("fine", fine)]).filter("ukf-turns").motion_models == ("ct-rate",)
