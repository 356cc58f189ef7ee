"""Every built-in sensor, discovered through the host exactly as a third-party one, passes the sensor kit:
detections centred on its own measurement model with the declared noise (a chi-square test), the same seed
giving the same scans, its declared frame respected, the target's origin label, its declared parameters."""

from workbench.plugins import load_host
from workbench.testing import parametrize_with_checks

_HOST = load_host()
BUILTIN = [spec for name, spec in sorted(_HOST.components["workbench_sensors"].items())
           if _HOST.plugin_of("workbench_sensors", name).distribution == "workbench"]


def test_the_built_in_sensors_are_discovered():
    assert len(BUILTIN) >= 4 and all(spec.kind == "sensor" for spec in BUILTIN)


@parametrize_with_checks(BUILTIN)
def test_conformance(spec, check):
    check(spec)
