"""``--filters``, ``--paper`` and ``--block`` follow the rules of a scenario file's ``[filters] names`` (issue 29,
class 8), with the same messages; ``workbench --version``; a Stone Soup filter without Stone Soup (class 10).

Every bad input goes through :func:`workbench.cli.main`, as a user's command line does, and must end with exit 2
and one ``workbench: error:`` line naming the mistake.  ``run_report`` is replaced by a function that fails the
test, so a request that should have been refused can never start a report.
"""

import os
import re
import subprocess
import sys
import textwrap
from importlib import metadata
from pathlib import Path

import pytest

from workbench.cli import main
from workbench.plugins import load_host

EXAMPLE = Path(__file__).parents[1] / "examples" / "scenarios" / "range_bearing.toml"


@pytest.fixture
def no_report(monkeypatch):
    """A report that starts is a failure of the check that should have refused its request first."""
    import workbench.report.engine as engine

    def refuse(*args, **kwargs):
        raise AssertionError("run_report started: the request was not refused before any paper ran")

    monkeypatch.setattr(engine, "run_report", refuse)


def _error(capsys, argv) -> str:
    """Run the command line; it must refuse with exit 2 and exactly one error line, which is returned."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = [line for line in err.splitlines() if line.startswith("workbench: error: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0][len("workbench: error: "):]


@pytest.mark.parametrize("request_, expected", [
    ("kf,kf", "--filters: the same filter is listed twice: 'kf'"),
    ("sir(particles=100),sir(particles=100)", "--filters: the same filter is listed twice: 'sir(particles=100)'"),
    ("sir(particles=100),sir( particles = 100 )",
     "--filters: the same filter is listed twice: 'sir(particles=100)' and 'sir( particles = 100 )' "
     "(both sir(particles=100))"),
    ("+kf,+kf", "--filters: the same filter is listed twice: 'kf'"),
    ("kf,+kf", "--filters: the same filter is listed twice: 'kf'"),
    ("-ekf,~ekf", "--filters: the same filter is listed twice: '-ekf'"),
    ("", "--filters: expected a non-empty list of filters"),
    (",", "--filters: expected a non-empty list of filters"),
    (" , ", "--filters: expected a non-empty list of filters"),
    ("kf,,ekf", "--filters '': an empty entry where a filter belongs"),
    ("kf,+", "--filters: entry 2 of 'kf,+' ('+') has no filter name after '+'"),
    ("range-bearing(sigma_theta=0.1)", "--filters 'range-bearing(sigma_theta=0.1)': 'range-bearing' is a sensor, "
                                       "not a filter"),
    ("kf,+radar-clutter", "--filters 'radar-clutter': 'radar-clutter' is a clutter generator, not a filter"),
    ("ekf,kalman-filter", "--filters 'kalman-filter': no filter named 'kalman-filter' is installed"),
])
def test_a_bad_filter_request_is_refused_before_any_paper_runs(capsys, no_report, tmp_path, request_, expected):
    message = _error(capsys, ["report", "--quick", "--out", str(tmp_path), "--no-progress", f"--filters={request_}"])
    assert message.startswith(expected), message


def test_a_filter_configured_with_its_own_defaults_is_the_plain_filter(capsys, no_report, tmp_path):
    # sir's default particle count, written out, configures nothing: it is the same filter as 'sir'
    particles = load_host().filter("sir").params["particles"]
    message = _error(capsys, ["report", "--quick", "--out", str(tmp_path), f"--filters=sir,sir(particles={particles})"])
    assert message == f"--filters: the same filter is listed twice: 'sir' and 'sir(particles={particles})' " \
                      f"(both sir)"


def test_filters_are_matched_by_what_they_are_not_how_they_are_spelled():
    from workbench.report.engine import resolve_filters

    host = load_host()
    defaults = ("kf", "sir(particles=100)")
    assert resolve_filters(defaults, "-sir( particles = 100 )", host) == ("kf",)
    assert resolve_filters(defaults, "+sir(particles=1e2)", host) == defaults  # 1e2 particles: the same filter
    assert resolve_filters(defaults, "+sir(particles=200)", host) == defaults + ("sir(particles=200)",)


def test_the_wrong_kind_names_what_it_is_and_the_installed_filters(capsys, no_report, tmp_path):
    message = _error(capsys, ["report", "--quick", "--out", str(tmp_path), "--filters", "range-bearing(sigma_theta=0.1)"])
    assert "no filter named" not in message  # the old, misleading message: the name is installed, as a sensor
    installed = re.search(r"installed filters: (.*)\)$", message).group(1).split(", ")
    assert installed == sorted(load_host().filters)


def test_filters_given_twice_is_refused(capsys, no_report, tmp_path):
    with pytest.raises(SystemExit) as info:
        main(["report", "--quick", "--out", str(tmp_path), "--filters", "kf", "--filters", "ekf"])
    assert info.value.code == 2
    assert "--filters is given twice ('kf' and 'ekf')" in capsys.readouterr().err


@pytest.mark.parametrize("papers, expected", [
    (["001", "001"], "--paper: the same paper is listed twice: '001'"),
    (["999"], "--paper '999': no paper '999' is installed (installed: "),
    (["001", "999"], "--paper '999': no paper '999' is installed (installed: "),  # refused before 001 runs
    ([""], "--paper '': no paper '' is installed (installed: "),
])
def test_a_bad_paper_request_is_refused_before_any_paper_runs(capsys, no_report, tmp_path, papers, expected):
    argv = ["report", "--quick", "--out", str(tmp_path)] + [f"--paper={p}" for p in papers]
    message = _error(capsys, argv)
    assert message.startswith(expected), message
    if "installed" in expected:
        # the installed papers, from the entry points' recipes (the host), every one of them
        assert message.split("(installed: ")[1].split(")")[0].split(", ") == sorted(load_host().recipes)


@pytest.mark.parametrize("blocks, expected", [
    (["kalman", "kalman"], "--block: the same plugin is listed twice: 'kalman'"),
    ([""], "--block '': expected a plugin name"),
])
@pytest.mark.parametrize("command", [["plugins"], ["--version"]])
def test_a_bad_block_list_is_refused(capsys, blocks, expected, command):
    argv = [a for b in blocks for a in ("--block", b)] + command
    assert _error(capsys, argv).startswith(expected)


def test_no_command_is_refused(capsys):
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2 and "required: command" in capsys.readouterr().err


# -- one rule, one message: a scenario file and --filters ------------------------------------------------------


def _scenario(tmp_path, names: str) -> Path:
    text = EXAMPLE.read_text().replace('names = ["ekf", "sir"]', f"names = {names}")
    text = text.replace("runs = 200", "runs = 2").replace("steps = 100", "steps = 5")
    assert f"names = {names}" in text
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


# (scenario [filters] names, the same list as --filters)
SAME_MISTAKE = [
    ('["kf", "kf"]', "kf,kf"),
    ('["sir(particles=100)", {name = "sir", particles = 100}]', "sir(particles=100),sir(particles=100)"),
    ('["sir(particles=100)", "sir( particles = 100 )"]', "sir(particles=100),sir( particles = 100 )"),
    ("[]", ""),
    ('[""]', ","),
    ('["kf", ""]', "kf,,"),
    ('["kf", " "]', "kf, ,ekf"),
    ('["ekf", "range-bearing(sigma_theta=0.1)"]', "ekf,range-bearing(sigma_theta=0.1)"),
    ('["range-bearing"]', "range-bearing"),
    ('["ekf", "ufk"]', "ekf,ufk"),
    ('["sir(particles=0)"]', "sir(particles=0)"),
    ('["sir(partcles=3)"]', "sir(partcles=3)"),
    ('["ss-ukf"]', "ss-ukf"),  # without Stone Soup: it needs Stone Soup; with it: a good list (checked below)
]


@pytest.mark.parametrize("names, request_", SAME_MISTAKE)
def test_a_scenario_file_and_the_command_line_give_the_same_message(capsys, no_report, tmp_path, names, request_):
    path = _scenario(tmp_path, names)
    out = tmp_path / "out"
    if names == '["ss-ukf"]' and "ss-ukf" in load_host().filters:
        pytest.skip("Stone Soup is installed: ss-ukf is a good filter here")
    from_file = _error(capsys, ["run", str(path), "--out", str(out)])
    from_cli = _error(capsys, ["report", "--quick", "--out", str(out), f"--filters={request_}"])
    # only the place named before the first ': ' differs (the file and key, or the option and the entry)
    where_file = re.match(re.escape(f"{path}: [filters] names") + r"(\[\d+\])?: ", from_file)
    where_cli = re.match(r"--filters( '[^']*')?: ", from_cli)
    assert where_file and where_cli, (from_file, from_cli)
    assert from_file[where_file.end():] == from_cli[where_cli.end():]
    assert not out.exists()  # neither route wrote anything


# -- --version --------------------------------------------------------------------------------------------------


def test_version_names_the_workbench_and_every_plugin_distribution(capsys):
    assert main(["--version"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"workbench {metadata.version('workbench')}"
    # every distribution with a workbench entry point, read from the installed metadata (not from the host)
    dists = {(ep.dist.metadata["Name"], ep.dist.version) for ep in metadata.entry_points(group="workbench")}
    assert dists and ("workbench", metadata.version("workbench")) in dists
    for name, version in dists:
        assert any(line.split()[:2] == [name, version] for line in out[1:]), (name, version, out)


def test_version_lists_a_third_party_distribution_and_a_blocked_plugin(tmp_path):
    (tmp_path / "fake_plugin.py").write_text("raise ImportError('missing dependency libfoo')\n")
    info = tmp_path / "fake_plugin-0.3.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-plugin\nVersion: 0.3\n")
    (info / "entry_points.txt").write_text("[workbench]\nfake = fake_plugin\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-m", "workbench.cli", "--block", "kalman", "--version"], env=env,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    fake = next(line for line in out.stdout.splitlines() if line.split()[:1] == ["fake-plugin"])
    assert fake.split()[1] == "0.3" and "fake (broken)" in fake
    assert "kalman (blocked)" in out.stdout


# -- a Stone Soup filter without Stone Soup ---------------------------------------------------------------------


@pytest.fixture
def no_stonesoup(tmp_path):
    """Stone Soup hidden from a fresh interpreter (installed or not) by a package of that name that fails."""
    fake = tmp_path / "hide" / "stonesoup"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError(\"No module named 'stonesoup' (hidden by a test)\")\n")
    return dict(os.environ, PYTHONPATH=str(tmp_path / "hide") + os.pathsep + os.environ.get("PYTHONPATH", ""))


INSTALL = 'pip install "workbench[stonesoup]"'


def test_building_a_stonesoup_filter_without_stonesoup_is_a_named_error(no_stonesoup):
    code = textwrap.dedent("""
        from workbench.types import InputError
        from workbench_interop.stonesoup_filters import make_gaussian, make_particle
        for name, build in [("ss-ukf", lambda: make_gaussian("ss-ukf")), ("ss-kf", lambda: make_gaussian("ss-kf")),
                            ("ss-pf", lambda: make_particle(particles=100))]:
            try:
                spec = build()
            except InputError as exc:
                assert isinstance(exc, ImportError), type(exc).__mro__
                print(f"{name}: {exc}")
            else:
                raise AssertionError(f"{name} was built without Stone Soup: {spec.name}")
        try:
            import workbench_interop.stonesoup_models
        except InputError as exc:
            print(f"models: {exc}")
    """)
    out = subprocess.run([sys.executable, "-c", code], env=no_stonesoup, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert [line.split(":")[0] for line in lines] == ["ss-ukf", "ss-kf", "ss-pf", "models"]
    for line in lines:
        assert "needs Stone Soup" in line and INSTALL in line and "hidden by a test" in line, line


@pytest.mark.parametrize("argv, where", [
    (["report", "--quick", "--filters", "kf,+ss-ukf"], "--filters 'ss-ukf': the filter 'ss-ukf' needs Stone Soup"),
    (["check-plugin", "ss-pf"], "the filter 'ss-pf' needs Stone Soup"),
    (["plugins", "ss-ekf"], "the filter 'ss-ekf' needs Stone Soup"),
])
def test_asking_for_a_stonesoup_filter_without_stonesoup_says_how_to_install_it(no_stonesoup, tmp_path, argv,
                                                                                 where):
    argv = argv[:1] + (["--out", str(tmp_path / "out")] if argv[0] == "report" else []) + argv[1:]
    out = subprocess.run([sys.executable, "-m", "workbench.cli", *argv], env=no_stonesoup, capture_output=True,
                         text=True)
    assert out.returncode == 2, out.stderr
    [line] = out.stderr.splitlines()
    assert line.startswith("workbench: error: ") and where in line and INSTALL in line, line
    assert not (tmp_path / "out").exists()
