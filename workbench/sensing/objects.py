"""Detections of several objects: a single-object sensor run once per object, merged into one scan series.

:func:`detect_objects` runs a sensor's own ``simulate`` (unchanged: a sensor plugin sees one object at a time, as
it always has) on each object of a :class:`~workbench.truth.MultiTruth`, in slot order, all from the one ``rng``::

    part_k = sensor.simulate(truth.object_truth(k), rng, **params, pd = p_d[k])   (pd only where p_d[k] is given)
    part_k.valid &= alive[:, :, k]            (no detection of an object before its birth or after its death)
    part_k.origin = k where the sensor labelled a detection of its target (origin >= 0), CLUTTER where it did not
    scans = merge of part_0 .. part_{K-1} along the detection axis

so every detection names the object it came from (``origin == k``), clutter keeps
:data:`~workbench.types.CLUTTER`.  An object's own detection probability is handed to the sensor as the value of its
P_D parameter (``pd_param``, ``"pd"`` by default); a sensor that declares no such parameter cannot honour one, and
a truth that gives one is refused, naming the sensor, the parameter and the object.  Objects that never live in any
run are not simulated (nothing of theirs could be detected); where no object lives at all, object 0's stand-in
states are simulated and every row is masked, so the scans keep the sensor's measurement dimension.
"""

from __future__ import annotations

import numpy as np

from ..types import CLUTTER, InputError, Scans

__all__ = ["detect_objects"]


def detect_objects(sensor, truth, rng: np.random.Generator, *, pd_param: str = "pd", **params) -> Scans:
    """Every object of ``truth`` (a :class:`~workbench.truth.MultiTruth`) seen by ``sensor`` (a
    :class:`~workbench.specs.SensorSpec`, with its configured values and ``params`` over them).

    Returns one :class:`~workbench.types.Scans`: ``z (B, T, M, m)`` with every object's detections side by side
    (``M`` the sum of each object's rows), ``origin (B, T, M)`` the object index of each detection."""
    from ..truth import MultiTruth

    if not isinstance(truth, MultiTruth):
        raise InputError(f"detect_objects takes a MultiTruth (several objects), got {type(truth).__name__}; a "
                         f"single-object Truth goes to the sensor's simulate, or through MultiTruth.from_truth")
    declared = {p.name for p in sensor.declared}
    parts = []
    never = not truth.alive.any()  # no object at all (a birth process that drew none): object 0, all masked
    for k in range(truth.objects):
        live = truth.alive[:, :, k]
        if not live.any() and not (never and k == 0):
            continue
        values = dict(params)
        if not np.isnan(truth.p_d[k]):
            if pd_param not in declared:
                raise InputError(f"object {k} ({truth.labels[k]}) has its own p_d = {truth.p_d[k]:g}, but sensor "
                                 f"{sensor.name!r} declares no parameter {pd_param!r} that sets its detection "
                                 f"probability (it declares {', '.join(sorted(declared)) or 'none'}); drop the "
                                 f"object's p_d or use a sensor with one")
            values[pd_param] = float(truth.p_d[k])
        part = sensor.simulate(truth.object_truth(k), rng, **values)
        if not isinstance(part, Scans) or part.z.shape[:2] != live.shape:
            raise InputError(f"sensor {sensor.name!r}: simulate returned "
                             f"{getattr(getattr(part, 'z', None), 'shape', type(part).__name__)} for one object over "
                             f"(runs, scans) {live.shape}; expected Scans of that shape")
        valid = part.valid & live[:, :, None]
        if part.origin is None:
            origin = np.full(valid.shape, k)
        else:
            origin = np.where(part.origin == CLUTTER, CLUTTER, k)
        parts.append(Scans(part.z, valid, part.times, snr=part.snr, doppler=part.doppler, origin=origin,
                           cov=part.cov, clutter_density=part.clutter_density))
    return Scans.merge_all(parts)
