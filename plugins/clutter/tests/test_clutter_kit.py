"""Every built-in clutter generator and remover, discovered through the host exactly as a third-party one, passes
the clutter kit: counts that follow the declared mean (Poisson), points inside the declared region, amplitudes
that follow the declared law (KS), every row labelled clutter; removers causal, blind to the origin labels and
only narrowing the valid mask."""

from workbench.plugins import load_host
from workbench.testing import parametrize_with_checks

_HOST = load_host()


def _builtin(hook):
    return [spec for name, spec in sorted(_HOST.components[hook].items())
            if _HOST.plugin_of(hook, name).distribution == "workbench"]


GENERATORS = _builtin("workbench_clutter_generators")
REMOVERS = _builtin("workbench_clutter_removers")


def test_the_built_in_clutter_components_are_discovered():
    assert len(GENERATORS) >= 3 and len(REMOVERS) >= 2


def test_every_built_in_generator_declares_what_the_kit_checks():
    for spec in GENERATORS:
        missing = [f for f in ("expected_count", "region", "amplitude_cdf") if getattr(spec, f) is None]
        assert not missing and spec.detection_frame(), (spec.name, missing)


@parametrize_with_checks(GENERATORS)
def test_generator_conformance(spec, check):
    check(spec)


@parametrize_with_checks(REMOVERS)
def test_remover_conformance(spec, check):
    check(spec)
