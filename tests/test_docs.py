"""Meta-tests: the plugin author's page covers every hook, capability and kit check."""

import inspect
from pathlib import Path

from workbench import hookspecs
from workbench.specs import CAPABILITIES
from workbench.testing import CHECKS, GENERATOR_CHECKS, REMOVER_CHECKS, SENSOR_CHECKS

ROOT = Path(__file__).parents[1]
GUIDE = (ROOT / "docs" / "writing-a-plugin.md").read_text()


def _hooks():
    return [name for name, fn in inspect.getmembers(hookspecs, inspect.isfunction) if name.startswith("workbench_")]


def test_every_hook_has_a_docstring_and_is_in_the_guide():
    assert len(_hooks()) == 9
    for name in _hooks():
        assert getattr(hookspecs, name).__doc__.strip(), name
        assert name in GUIDE, f"{name} is not mentioned in docs/writing-a-plugin.md"


def test_every_capability_and_check_is_documented():
    for cap in CAPABILITIES:
        assert f"`{cap}`" in GUIDE, cap
    for check in CHECKS:
        assert f"`{check.name}`" in GUIDE, check.name
        assert check.description and check.description.strip()


def test_every_sensor_and_clutter_check_is_documented():
    section = GUIDE[GUIDE.index("## 3. The tests"):]
    for kit, heading in ((SENSOR_CHECKS, "**Sensors**"), (GENERATOR_CHECKS, "**Clutter generators**"),
                         (REMOVER_CHECKS, "**Clutter removers**")):
        assert kit and heading in section, heading
        for check in kit:
            assert f"`{check.name}`" in section, (heading, check.name)
            assert check.description and check.description.strip(), check.name
    # what a component must declare for the kits
    for field in ("truth_to_state", "noise_cov", "expected_count", "region", "amplitude_cdf", "frames"):
        assert f"`{field}" in section, field


def test_readme_opens_with_the_two_commands():
    lines = (ROOT / "README.md").read_text().splitlines()
    block = lines[lines.index("```sh") + 1: lines.index("```sh") + 5]
    assert block[0].startswith("# 1.") and "workbench report" in block[1]
    assert block[2].startswith("# 2.") and "pytest" in block[3]
