"""pytest plugin (entry point ``pytest11``): fixtures for plugin authors.

- ``workbench_host``: a freshly built plugin host (never a shared global).
- ``workbench_filter``: factory ``workbench_filter(name)`` returning an installed filter's spec.
- ``workbench_motion_model``: factory ``workbench_motion_model(name, dt=1.0, **params)`` returning the
  :class:`~workbench.models.MotionModel` an installed motion model builds (``name`` may carry parameters:
  ``"ct-rate(sigma_omega=0.01)"``); check it with ``workbench.testing.run_checks`` or ``parametrize_with_checks``.
- ``workbench_tracker``: factory ``workbench_tracker(name)`` returning an installed tracker's spec (``name`` may
  carry parameters: ``"gnn(gate_probability=0.95)"``); ``parametrize_with_checks([spec])`` collects the tracker
  kit's checks (:mod:`workbench.testing.trackers`) as it collects a filter's.
"""

from __future__ import annotations

import pytest


@pytest.fixture
def workbench_host():
    from workbench.plugins import load_host

    return load_host()


@pytest.fixture
def workbench_filter(workbench_host):
    return workbench_host.filter


@pytest.fixture
def workbench_motion_model(workbench_host):
    return workbench_host.motion_model


@pytest.fixture
def workbench_tracker(workbench_host):
    return workbench_host.tracker
