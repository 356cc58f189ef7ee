"""Paper 000's methods (Table 1) as rows of the comparison, and one gated run of a method.

The paper compares (A) an EKF and (B) a bootstrap particle filter, both fed one weighted-mean pseudo-measurement
per scan (eqs 9-11), with (C) a particle filter weighted directly by every gated detection (eqs 12-15).  Each row
of :data:`METHODS` names a filter (a reference the plugin host resolves, configured through its declared
parameters, e.g. ``"tbd-pf(floor=flat)"``), the form of the pseudo-measurement it is given (:data:`PSEUDO_FORMS`)
and its role in the report:

- ``"A"``, ``"B"``, ``"C"``: the rows the paper's criteria judge.  A and B are the paper's as it writes them
  (Table 1, eqs 9-11): the pseudo-measurement is a weighted-mean *coordinate* ``z_bar = sum_m w~_m p_m`` (form
  ``"position"``), the Doppler entering only the weights (eq 10), given with the fixed ``R_bar = diag(300^2,
  300^2, 300^2)`` (the sensor's stated pseudo-measurement accuracy, a value the paper withholds: the brief's
  reading) and no clutter term to a plain ``ekf`` and a plain bootstrap ``sir`` with one Gaussian process noise.
- ``"ablation"`` rows ``A-4v``, ``B-4v``: the brief's earlier reading of eq 11, the 4-vector ``[p; v_r]`` with
  ``R_bar = diag(300^2, 300^2, 300^2, 10^2)`` (form ``"vector"``).
- ``"ours"``: our stronger A and B (labelled as improvements): the PDA-like ``R_bar`` and the clutter term of the
  pseudo-measurement, the NIS-switched EKF and the two-mode particle filter.
- ``"ablation"``: method C with one of its changes undone.

What a filter is given never depends on its name: the pseudo-measurement form is the row's declaration, the
clutter term goes to filters that declare the ``clutter_density`` capability, a per-measurement ``R_bar`` to those
that declare ``detection_covariance`` (the others get the whitened pseudo-measurement), and the manoeuvre model to
those that declare ``manoeuvre_modes``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from workbench.models import MeasurementModel, MotionModel, constant_velocity
from workbench.rng import generator
from workbench.types import Gaussian, Scan, Scans

from .pipeline import estimation_error, lost_track, moment_matched_scale, position_model, \
    pseudo_measurement_covariance, run_gated, weighted_mean_measurement, weighted_mean_position, whitened_model
from .scenario import DT, START_POSITION, clutter_for, clutter_intensity, scenario_truth

__all__ = ["Method", "METHODS", "PSEUDO_FORMS", "ROLES", "CLUTTER_TERMS", "CLUTTER_TERM", "clutter_term_of", "SIGMA_A", "PRIOR_SD", "SIGMA_G", "SIGMA_D",
           "TRACK_THRESHOLD_DB", "LOST_LIMIT_M", "LOST_SCANS", "PROPOSED", "method_for", "rows_for", "method_of",
           "with_particles",
           "motion_for", "clutter_floor", "clutter_amplitude_ratio", "pseudo_measurement", "run_method"]

SIGMA_A = (8.0, 8.0, 4.0)  # m/s^2 per axis, the quiet mode of every method [U, chosen on tuning seeds]
PRIOR_SD = (500.0, 500.0, 300.0, 30.0, 30.0, 10.0)  # around the true initial state [U]
TRACK_THRESHOLD_DB = 5.0  # every tracking result [S]
SIGMA_G = 500.0  # m, weighted-mean kernel (eq 10) [U]
SIGMA_D = 15.0  # m/s, weighted-mean Doppler kernel (eq 10) [U]
LOST_LIMIT_M, LOST_SCANS = 3000.0, 5
#: the proposed filter (method C), whose two-mode noise sets the single noise of the filters without modes
PROPOSED = "tbd-pf"
#: ``"position"``: eqs 9-11 as the paper writes them, the weighted-mean coordinate with the fixed position R_bar, no
#: clutter term; ``"vector"``: the 4-vector ``[p; v_r]`` reading with the model's fixed R; ``"pda"``: the PDA-like
#: R_bar + clutter term (our A and B)
PSEUDO_FORMS = ("position", "vector", "pda", "")
ROLES = ("A", "B", "C", "ours", "ablation", "extra")
#: the clutter term ``b`` of our A and B: none; the clutter intensity ``lambda`` (flat); ``lambda`` x the clutter
#: amplitude law at the strongest detection (amplitude); ``lambda (1 - P_D) / P_D`` x that law (pd-amplitude)
CLUTTER_TERMS = ("none", "flat", "amplitude", "pd-amplitude")
#: the clutter term our A and B use [chosen on tuning seeds, docs/paper000.md]
CLUTTER_TERM = "pd-amplitude"


@dataclass(frozen=True)
class Method:
    """One row of the comparison: ``key`` (short, for task keys), ``label`` (the report's), ``filter`` (a reference
    the host resolves), ``pseudo`` (the pseudo-measurement form, ``""`` for a multi-measurement filter) and
    ``role`` (:data:`ROLES`)."""

    key: str
    label: str
    filter: str
    pseudo: str
    role: str

    def __post_init__(self) -> None:
        if self.pseudo not in PSEUDO_FORMS or self.role not in ROLES:
            raise ValueError(f"method {self.key!r}: pseudo must be one of {PSEUDO_FORMS}, role one of {ROLES}")


METHODS = (
    Method("A", "(A) EKF, weighted-mean coordinate (eqs 9-11); R_bar 300 m: brief's reading", "ekf", "position",
           "A"),
    Method("B", "(B) PF, weighted-mean coordinate (eqs 9-11); R_bar 300 m: brief's reading", "sir", "position",
           "B"),
    Method("C", "(C) direct weights, amplitude-aware floor", PROPOSED, "", "C"),
    Method("A+", "A, ours: PDA update, R_bar, NIS noise", "ekf-nis", "pda", "ours"),
    Method("B+", "B, ours: clutter mixture, R_bar, two-mode", "sir-jm", "pda", "ours"),
    Method("C-flat", "C with the previous flat floor", f"{PROPOSED}(floor=flat)", "", "ablation"),
    Method("C-none", "C without a floor (eqs 13-15 as printed)", f"{PROPOSED}(floor=none)", "", "ablation"),
    Method("C-2ms", "C with the sensor's 2 m/s Doppler kernel", f"{PROPOSED}(sigma_vr=2)", "", "ablation"),
    Method("A-4v", "A (4-vector reading): z_bar = [p; v_r], R_bar 300 m / 10 m/s (brief's reading)", "ekf",
           "vector", "ablation"),
    Method("B-4v", "B (4-vector reading): z_bar = [p; v_r], R_bar 300 m / 10 m/s (brief's reading)", "sir",
           "vector", "ablation"),
)


def rows_for(reference: str, capabilities=frozenset()) -> tuple[Method, ...]:
    """Every row of filter ``reference`` (``"ekf"`` is A and its 4-vector ablation), in :data:`METHODS` order; for a
    filter no row names, one extra row (``--filters``), which gets our pseudo-measurement (PDA-like ``R_bar``) unless
    it takes every detection (``multi_measurement``)."""
    rows = tuple(m for m in METHODS if m.filter == reference)
    return rows or (Method(reference, reference, reference, "" if "multi_measurement" in capabilities else "pda",
                           "extra"),)


def method_for(reference: str, capabilities=frozenset()) -> Method:
    """The first row of filter ``reference`` (:func:`rows_for`): the judged row where the filter has one."""
    return rows_for(reference, capabilities)[0]


def method_of(key: str, reference: str | None = None, capabilities=frozenset()) -> Method:
    """The row with ``key`` (:data:`METHODS`), else the extra row of filter ``reference`` (default: ``key``)."""
    for m in METHODS:
        if m.key == key:
            return m
    return method_for(reference or key, capabilities)


def with_particles(spec, particles: int | None):
    """``spec`` configured with ``particles`` particles (filters that declare a ``particles`` parameter; others as
    they are), keeping its name."""
    if particles is None or "particles" not in {p.name for p in spec.declared}:
        return spec
    return spec.configure(particles=int(particles), name=spec.name)


def motion_for(spec, proposed, sigma_a=SIGMA_A) -> MotionModel:
    """The CV model a filter runs with: the quiet ``sigma_a`` for a filter with a manoeuvre mode of its own (the
    ``manoeuvre_modes`` capability: the two-mode particle filters, the NIS-switched EKF), otherwise one Gaussian
    noise with the same stationary covariance as the proposed filter's two-mode noise (``sigma_a`` x
    :func:`moment_matched_scale` of its declared ``switch_on``, ``switch_off``, ``manoeuvre_scale``)."""
    if "manoeuvre_modes" in spec.capabilities:
        return constant_velocity(3, DT, sigma_a)
    p = proposed.params
    factor = moment_matched_scale(p["switch_on"], p["switch_off"], p["manoeuvre_scale"])
    return constant_velocity(3, DT, tuple(factor * s for s in sigma_a))


def clutter_floor(host, model: MeasurementModel, threshold_db: float = TRACK_THRESHOLD_DB,
                  rate: float | None = None) -> tuple[float, float, float]:
    """The clutter term of our A and B, from the clutter and sensor models: ``(b, lambda, P_D)``.

    ``lambda`` is the clutter model's intensity per unit measurement volume ``(x, y, z, vr)`` at the threshold
    (its declared mean count over its region, :func:`~.scenario.clutter_intensity`).  The probabilistic data
    association filter's "the measurement is clutter" term is ``b = lambda (1 - P_D) / P_D``; ``P_D`` is the
    sensor's declared detection probability of its design target at the track start
    (``detection.log_detection(detection.nominal_snr_db(p_0))``).
    """
    truth = scenario_truth(1)
    lam = float(np.max(clutter_intensity(clutter_for(host, threshold_db, rate), truth)))
    d = model.detection
    pd = float(np.exp(d.log_detection(d.nominal_snr_db(np.asarray(START_POSITION)))))
    # b = lambda (1 - P_D) / P_D
    return lam * (1.0 - pd) / pd, lam, pd


def clutter_term_of(host, model: MeasurementModel, term: str = CLUTTER_TERM,
                    threshold_db: float = TRACK_THRESHOLD_DB, rate: float | None = None) -> tuple[float, bool]:
    """``(b, amplitude)`` of the clutter term ``term`` (:data:`CLUTTER_TERMS`): the density at the threshold and
    whether it is scaled by the clutter amplitude law at the strongest gated detection."""
    if term not in CLUTTER_TERMS:
        raise ValueError(f"unknown clutter term {term!r}; expected one of {CLUTTER_TERMS}")
    if term == "none":
        return 0.0, False
    b, lam, _ = clutter_floor(host, model, threshold_db, rate)
    return (b if term == "pd-amplitude" else lam), term != "flat"


def clutter_amplitude_ratio(gated, mean_power: float, threshold_db: float) -> np.ndarray:
    """``exp(-(p_max - t) / mu)`` per item: the density of clutter (exponential power, mean ``mu``) at the
    power ``p_max`` of the strongest gated detection, relative to its density at the threshold ``t`` (1 for
    an item without detections)."""
    from workbench.sensing.radar import from_db

    snr = np.where(gated.valid, np.nan_to_num(gated.snr, nan=-np.inf), -np.inf)
    top = np.max(snr, axis=1, initial=-np.inf)
    excess = np.where(np.isfinite(top), from_db(np.where(np.isfinite(top), top, threshold_db)) - from_db(threshold_db),
                      0.0)
    # f_0(p) / f_0(t) = exp(-(p - t) / mu)
    return np.exp(-np.maximum(excess, 0.0) / mean_power)


def pseudo_measurement(gated, predicted, rng=None, *, model, filt, form: str, clutter_density: float = 0.0,
                       amplitude_mean_power: float | None = None, threshold_db: float = TRACK_THRESHOLD_DB,
                       position: MeasurementModel | None = None):
    """Methods A and B: the weighted-mean pseudo-measurement (eqs 9-11) at the recipe's kernel widths.

    ``form = "position"`` (the paper's A and B): the weighted-mean coordinate ``z_bar = sum_m w~_m p_m``
    (:func:`~.pipeline.weighted_mean_position`, the Doppler only in the weights) with its model ``position``
    (:func:`~.pipeline.position_model` of ``model``: ``h(s) = p``, the fixed ``R_bar`` of the sensor's stated
    position accuracy), returned as the pair ``(Scan, MeasurementModel)``; no clutter term.
    ``form = "vector"`` (the 4-vector reading): ``z_bar = sum_m w~_m [p_m; vr_m]`` alone; the filter uses the model's
    fixed ``R`` (the brief's ``R_bar``), no clutter term.  ``form = "pda"``: with its PDA-like noise ``R_bar`` (SNR-based detection accuracy + spread of the gated
    detections + the Doppler mismatch to the prediction) as the scan's own covariance and, for a filter with the
    ``clutter_density`` capability and ``clutter_density = b > 0``, the clutter density at the measurement: ``b``
    times the clutter amplitude law at the strongest gated detection (:func:`clutter_amplitude_ratio`).  A filter
    without the ``detection_covariance`` capability gets the whitened ``(Scan, MeasurementModel)`` pair instead.
    """
    if form == "position":
        return (weighted_mean_position(gated, predicted, model, SIGMA_G, SIGMA_D),
                position_model(model) if position is None else position)
    if form == "vector":
        return weighted_mean_measurement(gated, predicted, model, SIGMA_G, SIGMA_D)
    z_bar, r_bar = pseudo_measurement_covariance(gated, predicted, model, SIGMA_G, SIGMA_D, doppler_mismatch=True)
    if "detection_covariance" not in filt.capabilities:
        return whitened_model(model, z_bar, r_bar)
    density = None
    if clutter_density > 0.0 and "clutter_density" in filt.capabilities:
        ratio = clutter_amplitude_ratio(gated, amplitude_mean_power, threshold_db) \
            if amplitude_mean_power is not None else np.ones(gated.batch)
        density = clutter_density * ratio
    return Scan.single(z_bar.z[:, 0], z_bar.valid[:, 0], time=z_bar.time, cov=r_bar, clutter_density=density)


def run_method(host, method: Method, scans: Scans, truth: np.ndarray, model: MeasurementModel, *, radius: float,
               particles: int | None, seed: int, rng_key: tuple = (), sigma_a=None, proposed=None, spec=None,
               clutter_term: str | None = None, threshold_db: float = TRACK_THRESHOLD_DB,
               record: bool = True, clutter_rate: float | None = None) -> dict[str, np.ndarray]:
    """One method over ``scans`` (gate of ``radius``): errors (eq 20), measurement errors (eq 19), lost flags and the
    warmed-up wall time of the tracking loop.

    ``spec`` replaces the row's filter (a configured one, e.g. in the tuning search), ``sigma_a`` the quiet process
    noise, ``proposed`` the filter whose two-mode noise the filters without modes match, ``clutter_term`` the clutter
    term of a ``"pda"`` row (:data:`CLUTTER_TERMS`), ``clutter_rate`` the clutter rate the scans were drawn at (the
    declared unknown; None: the clutter model's declared rate), which that term is computed at.

    Shapes: ``truth (B, T, 6)``; returns ``error, m_error (B, T)``, ``lost (B,)``, ``gated (B, T)``, ``path0 (T, 3)``,
    ``gated0 (K, 6)``, ``seconds ()`` (wall) and ``cpu_seconds ()`` (this process's CPU time, all threads: what
    other jobs on the machine change least), both of the tracking loop alone (:func:`~.pipeline.run_gated`).
    """
    spec = with_particles(host.filter(method.filter) if spec is None else spec, particles)
    proposed = host.filter(PROPOSED) if proposed is None else proposed
    motion = motion_for(spec, proposed, SIGMA_A if sigma_a is None else sigma_a)
    runs = scans.batch
    prior = Gaussian.broadcast(truth[0, 0], np.diag(np.square(PRIOR_SD)), runs)
    clutter = clutter_for(host, threshold_db, clutter_rate)
    b, amplitude = clutter_term_of(host, model, clutter_term or CLUTTER_TERM, threshold_db, clutter_rate) \
        if method.pseudo == "pda" else (0.0, False)
    pseudo = partial(pseudo_measurement, model=model, filt=spec, form=method.pseudo or "pda", clutter_density=b,
                     amplitude_mean_power=float(clutter.params["mean_power"]) if amplitude else None,
                     threshold_db=threshold_db, position=position_model(model) if method.pseudo == "position" else None)
    # compile any kernel and warm every cache first, so that the timed run measures tracking only
    run_gated(spec, prior, motion, model, scans.head(3), radius, generator(seed, "paper000", "warm-up"), pseudo=pseudo)
    # the rows of one filter (A and its 4-vector ablation) draw from the same stream: they differ only in the form
    rng = generator(seed, "paper000", "track", method.filter, particles or 0, radius, *rng_key)
    out = run_gated(spec, prior, motion, model, scans, radius, rng, truth=truth if record else None, pseudo=pseudo)
    error = estimation_error(out.mean, truth)
    return {"error": error, "m_error": out.measurement_error, "gated": out.gated_count, "path0": out.mean[0, :, :3],
            "lost": lost_track(error, LOST_LIMIT_M, LOST_SCANS), "seconds": np.array(out.seconds),
            "cpu_seconds": np.array(out.cpu_seconds), "gated0": out.gated_points}
