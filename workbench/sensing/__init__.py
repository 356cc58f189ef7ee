"""Sensor physics that several plugins share: monostatic radar (:mod:`.radar`) and bistatic geometry
(:mod:`.bistatic`).  A sensor, a clutter model and a filter that all need the radar equation or the bistatic
range rate read it from here, so that plugins never import each other.  :func:`detect_objects` (:mod:`.objects`)
runs a single-object sensor on every object of a :class:`~workbench.truth.MultiTruth`."""

from .objects import detect_objects

__all__ = ["detect_objects"]
