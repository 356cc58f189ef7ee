"""The optional extras in pyproject.toml: a package named in several extras has one minimum version, and the README
names every extra."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_a_package_in_several_extras_asks_for_the_same_version_everywhere():
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    seen: dict[str, tuple[str, str]] = {}
    for extra, requirements in extras.items():
        for requirement in requirements:
            name, spec = re.match(r"\s*([A-Za-z0-9_.-]+)\s*(.*)", requirement).groups()
            key = name.lower().replace("_", "-")
            if key in seen:
                assert seen[key][1] == spec.strip(), (
                    f"{name}: {seen[key][1]!r} in [{seen[key][0]}] but {spec.strip()!r} in [{extra}]")
            else:
                seen[key] = (extra, spec.strip())


def test_the_readme_names_every_extra():
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    readme = (ROOT / "README.md").read_text()
    missing = [e for e in extras if f".[{e}]" not in readme]
    assert not missing, f"the README does not name the extras {missing}"
