"""Several objects per run: a multi-object truth record with identities, births and deaths.

:class:`MultiTruth` holds ``K`` object slots per run: ``states (B, T, K, n)`` with an ``alive (B, T, K)`` mask
(each object exists over one interval of scans, from its birth to its death) at ``times (T,)``.  Slot ``k`` is the
object's identity: a sensor's detection of it carries ``origin == k`` (:func:`workbench.sensing.detect_objects`),
clutter keeps :data:`~workbench.types.CLUTTER`.  States where an object is not alive are NaN (it has no state
there); every metric reads them through the mask.

Objects come from two declared sources, simulated by :func:`simulate_objects`:

- :class:`ObjectSpec`: a listed target with its start state at scan ``first``, its own motion model (the
  scenario's by default: constant velocity), its own detection probability (the sensor's by default) and its last
  scan (the run's end by default);
- :class:`BirthProcess`: ``Poisson(rate)`` births per scan (from the second scan on), each at a position uniform
  in a rectangular region with a velocity ``N(velocity_mean, velocity_std^2)`` per axis, surviving each later scan
  with probability ``survival``; at most ``max_objects`` births per run (a run that draws more is refused, naming
  ``max_objects``).

Every object moves as :func:`workbench.trajectory.sample_motion` moves a single target: ``x_k = f(x_{k-1}) + Q_sqrt
e_k`` with its motion model bound to each step's absolute time.  Every draw comes from ``generator(seed, *key,
...)``: one stream per listed target (``"target", j``) and one for the birth process (``"births"``), so adding a
target does not move the others.  The single-object :class:`~workbench.types.Truth` is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .models import MotionModel
from .rng import generator
from .trajectory import sample_motion
from .types import InputError, Truth, _array, _as_array, check_size, real_scalar

__all__ = ["MultiTruth", "ObjectSpec", "BirthProcess", "simulate_objects"]


@dataclass(frozen=True)
class MultiTruth:
    """True states of several objects per run.

    Shapes
    ------
    states : (B, T, K, n); NaN where the object is not alive
    alive : (B, T, K) bool; for each run and slot, one interval of scans (or none)
    times : (T,)
    p_d : (K,) float; each object's own detection probability, NaN where the sensor's applies
    labels : K names (``"target 0"``, ``"born"``)
    """

    states: np.ndarray
    alive: np.ndarray
    times: np.ndarray
    p_d: np.ndarray | None = None
    labels: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        states = _array("MultiTruth.states", self.states, 4)
        alive = _array("MultiTruth.alive", self.alive, 3, dtype=bool)
        times = _array("MultiTruth.times", self.times, 1)
        B, T, K, n = states.shape
        if alive.shape != (B, T, K):
            raise InputError(f"MultiTruth.alive must have shape {(B, T, K)} to match states {states.shape}, got "
                             f"{alive.shape}")
        if times.shape != (T,):
            raise InputError(f"MultiTruth.times must have length {T}, got {times.shape[0]}")
        if not np.all(np.isfinite(times)) or (T > 1 and np.any(np.diff(times) <= 0)):
            raise InputError("MultiTruth.times must be finite and strictly increasing")
        bad = alive & ~np.all(np.isfinite(states), axis=-1)
        if bad.any():
            raise InputError(f"MultiTruth.states holds NaN or inf for a live object at (run, scan, object) "
                             f"{tuple(int(i) for i in np.argwhere(bad)[0])}")
        # one interval per (run, object): alive switches on at most once and off at most once
        a = alive.astype(np.int8)
        starts = np.sum(np.diff(a, axis=1, prepend=0) == 1, axis=1)
        if np.any(starts > 1):
            b, k = (int(i) for i in np.argwhere(starts > 1)[0])
            raise InputError(f"MultiTruth.alive: object {k} of run {b} is born more than once (an object exists "
                             f"over one interval of scans; a new object takes a new slot)")
        p_d = np.full(K, np.nan) if self.p_d is None else _as_array("MultiTruth.p_d", self.p_d)
        if p_d.shape != (K,):
            raise InputError(f"MultiTruth.p_d must have shape ({K},), one per object, got {p_d.shape}")
        given = ~np.isnan(p_d)
        if np.any(given & ~((p_d >= 0) & (p_d <= 1))):
            raise InputError(f"MultiTruth.p_d must lie in [0, 1] (NaN: the sensor's own), got {p_d.tolist()}")
        labels = tuple(self.labels) or tuple(f"object {k}" for k in range(K))
        if len(labels) != K:
            raise InputError(f"MultiTruth.labels must name the {K} objects, got {len(labels)} names")
        object.__setattr__(self, "states", np.where(alive[..., None], states, np.nan))
        object.__setattr__(self, "alive", alive)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "p_d", p_d)
        object.__setattr__(self, "labels", labels)

    @property
    def batch(self) -> int:
        return self.states.shape[0]

    @property
    def steps(self) -> int:
        return self.states.shape[1]

    @property
    def objects(self) -> int:
        """The number of object slots ``K``."""
        return self.states.shape[2]

    @property
    def dim(self) -> int:
        return self.states.shape[3]

    def counts(self) -> np.ndarray:
        """Live objects per run and scan, ``(B, T)``."""
        return self.alive.sum(axis=2)

    def object_truth(self, k: int) -> Truth:
        """Object ``k`` as a single-object :class:`~workbench.types.Truth` for a sensor's ``simulate``: its states
        where it is alive, and finite stand-ins elsewhere (the first live state before its birth, the last after
        its death, the first live state of any run for a run where it never lives, zeros where it never lives at
        all), which :func:`workbench.sensing.detect_objects` masks out."""
        k = int(k)
        if not 0 <= k < self.objects:
            raise InputError(f"MultiTruth.object_truth: object {k} is not one of the {self.objects} objects")
        x = self.states[:, :, k]
        live = self.alive[:, :, k]
        T = self.steps
        idx = np.arange(T)
        ever = live.any(axis=1)
        first = np.where(ever, np.argmax(live, axis=1), 0)
        last = np.where(ever, T - 1 - np.argmax(live[:, ::-1], axis=1), 0)
        pick = np.clip(idx[None, :], first[:, None], last[:, None])  # hold the first / last live state
        out = np.take_along_axis(x, pick[..., None], axis=1)
        if not ever.all():
            fill = x[int(np.argmax(ever)), first[int(np.argmax(ever))]] if ever.any() else np.zeros(self.dim)
            out[~ever] = fill
        return Truth(out, self.times, labels=(self.labels[k],))

    def as_truth(self) -> Truth:
        """A single-object view for components that take a :class:`~workbench.types.Truth` for its shape and
        times only (clutter generators): object 0's :meth:`object_truth`."""
        return self.object_truth(0)

    @classmethod
    def from_truth(cls, truth: Truth) -> "MultiTruth":
        """A single-object :class:`~workbench.types.Truth` as one always-alive object."""
        return cls(truth.states[:, :, None, :], np.ones(truth.states.shape[:2] + (1,), dtype=bool), truth.times,
                   labels=tuple(truth.labels[:1]) or ("object 0",))


@dataclass(frozen=True)
class ObjectSpec:
    """One listed target.

    initial_state : (n,), its state at scan ``first``
    initial_std : (n,) or None, a per-run spread drawn around it (``N(0, std^2)`` per component)
    motion : its own :class:`~workbench.models.MotionModel`, or None for the scenario's
    p_d : its own detection probability in [0, 1], or None for the sensor's
    first : the scan it is born at (0: present from the start)
    last : the last scan it is alive at (inclusive), or None: to the end
    label : its name
    """

    initial_state: np.ndarray
    initial_std: np.ndarray | None = None
    motion: MotionModel | None = None
    p_d: float | None = None
    first: int = 0
    last: int | None = None
    label: str = ""

    def __post_init__(self) -> None:
        x0 = _as_array("ObjectSpec.initial_state", self.initial_state)
        if x0.ndim != 1 or not np.all(np.isfinite(x0)):
            raise InputError(f"ObjectSpec.initial_state must be a finite vector, got {x0.tolist()}")
        object.__setattr__(self, "initial_state", x0)
        if self.initial_std is not None:
            std = _as_array("ObjectSpec.initial_std", self.initial_std)
            if std.shape != x0.shape or not np.all(np.isfinite(std)) or np.any(std < 0):
                raise InputError(f"ObjectSpec.initial_std must be {x0.size} finite values >= 0, got {std.tolist()}")
            object.__setattr__(self, "initial_std", std)
        if self.p_d is not None:
            p = real_scalar("ObjectSpec.p_d", self.p_d)
            if not 0.0 <= p <= 1.0:
                raise InputError(f"ObjectSpec.p_d must lie in [0, 1], got {p}")
            object.__setattr__(self, "p_d", p)
        first = check_size("ObjectSpec.first", self.first, 1.0, minimum=0)
        object.__setattr__(self, "first", first)
        if self.last is not None:
            last = check_size("ObjectSpec.last", self.last, 1.0, minimum=0)
            if last < first:
                raise InputError(f"ObjectSpec.last = {last} comes before first = {first}")
            object.__setattr__(self, "last", last)


@dataclass(frozen=True)
class BirthProcess:
    """Objects born at random: ``Poisson(rate)`` births per scan from scan 1 on.

    rate : expected births per scan (>= 0)
    region : ``d`` pairs ``(low, high)``, one per position axis: the birth position is uniform in the box
    velocity_std : (d,) or a number: the birth velocity's standard deviation per axis
    velocity_mean : (d,) or a number (0): its mean
    max_objects : the most births one run may hold; a run that draws more is refused, naming this key
    survival : probability that a born object lives on from one scan to the next (1: to the run's end)
    p_d : the born objects' own detection probability, or None for the sensor's
    """

    rate: float
    region: Sequence[Sequence[float]]
    velocity_std: float | Sequence[float]
    max_objects: int
    velocity_mean: float | Sequence[float] = 0.0
    survival: float = 1.0
    p_d: float | None = None

    def __post_init__(self) -> None:
        rate = real_scalar("BirthProcess.rate", self.rate)
        if not (np.isfinite(rate) and rate >= 0):
            raise InputError(f"BirthProcess.rate must be a finite number >= 0 (births per scan), got {rate}")
        region = _as_array("BirthProcess.region", self.region)
        if region.ndim != 2 or region.shape[1] != 2 or region.shape[0] < 1:
            raise InputError(f"BirthProcess.region must be one (low, high) pair per position axis, got shape "
                             f"{region.shape}")
        if not np.all(np.isfinite(region)) or np.any(region[:, 0] >= region[:, 1]):
            raise InputError(f"BirthProcess.region: every pair must be finite with low < high, got {region.tolist()}")
        d = region.shape[0]
        for name in ("velocity_std", "velocity_mean"):
            v = np.broadcast_to(_as_array(f"BirthProcess.{name}", getattr(self, name)), (d,)).copy() \
                if np.ndim(getattr(self, name)) == 0 else _as_array(f"BirthProcess.{name}", getattr(self, name))
            if v.shape != (d,) or not np.all(np.isfinite(v)):
                raise InputError(f"BirthProcess.{name} must be a number or {d} finite numbers (one per axis of the "
                                 f"region), got {np.asarray(getattr(self, name)).tolist()}")
            if name == "velocity_std" and np.any(v < 0):
                raise InputError(f"BirthProcess.velocity_std must be >= 0, got {v.tolist()}")
            object.__setattr__(self, name, v)
        survival = real_scalar("BirthProcess.survival", self.survival)
        if not 0.0 < survival <= 1.0:
            raise InputError(f"BirthProcess.survival must lie in (0, 1], got {survival}")
        if self.p_d is not None:
            p = real_scalar("BirthProcess.p_d", self.p_d)
            if not 0.0 <= p <= 1.0:
                raise InputError(f"BirthProcess.p_d must lie in [0, 1], got {p}")
            object.__setattr__(self, "p_d", p)
        object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "region", region)
        object.__setattr__(self, "survival", survival)
        object.__setattr__(self, "max_objects", check_size("BirthProcess.max_objects", self.max_objects, 1.0,
                                                           minimum=1))

    @property
    def dims(self) -> int:
        return self.region.shape[0]


def _check_motion(motion: MotionModel, n: int, dt: float, who: str) -> None:
    if motion.dim != n:
        raise InputError(f"{who}: its motion model {motion.name!r} has a state of {motion.dim} components, but the "
                         f"objects' states have {n}")
    if abs(motion.dt - dt) > 1e-9 * max(1.0, dt):
        raise InputError(f"{who}: its motion model {motion.name!r} steps {motion.dt:g} s, but the scans are {dt:g} s "
                         f"apart")


def simulate_objects(targets: Sequence[ObjectSpec] = (), births: BirthProcess | None = None, *, runs: int,
                     steps: int, motion: MotionModel, seed: int, key: Sequence = (), t0: float = 0.0) -> MultiTruth:
    """The listed ``targets`` (slots ``0 .. len(targets) - 1``) and, with ``births``, up to
    ``births.max_objects`` born objects (the following slots, in order of birth in each run), for ``runs`` runs of
    ``steps`` scans ``motion.dt`` apart from ``t0``.  ``motion`` moves every object that has none of its own, and
    every born object; its state is ``[p (d), v (d)]`` for a birth process of ``d`` position axes."""
    runs = check_size("simulate_objects: runs", runs, 1.0)
    steps = check_size("simulate_objects: steps", steps, 1.0)
    if not targets and births is None:
        raise InputError("simulate_objects: give at least one target or a birth process")
    n, dt = motion.dim, float(motion.dt)
    times = float(t0) + dt * np.arange(steps)
    slots = len(targets) + (births.max_objects if births is not None else 0)
    check_size("simulate_objects: runs x steps x objects", runs * steps * slots, 8.0 * (n + 1))
    states = np.full((runs, steps, slots, n), np.nan)
    alive = np.zeros((runs, steps, slots), dtype=bool)
    p_d = np.full(slots, np.nan)
    labels: list[str] = []
    for j, obj in enumerate(targets):
        who = f"target {j}" + (f" ({obj.label})" if obj.label else "")
        moved = obj.motion or motion
        _check_motion(moved, n, dt, who)
        if obj.initial_state.shape != (n,):
            raise InputError(f"{who}: initial_state has {obj.initial_state.size} components, the state has {n}")
        last = steps - 1 if obj.last is None else obj.last
        if obj.first >= steps or last >= steps:
            raise InputError(f"{who}: alive from scan {obj.first} to scan {last}, but the run has scans 0 to "
                             f"{steps - 1}")
        rng = generator(seed, *key, "target", j)
        x0 = np.broadcast_to(obj.initial_state, (runs, n)).copy()
        if obj.initial_std is not None:
            x0 = x0 + rng.standard_normal((runs, n)) * obj.initial_std
        path = sample_motion(x0, moved, last - obj.first + 1, rng, t0=float(times[obj.first]))
        states[:, obj.first:last + 1, j] = path.states
        alive[:, obj.first:last + 1, j] = True
        p_d[j] = np.nan if obj.p_d is None else obj.p_d
        labels.append(obj.label or f"target {j}")
    if births is not None:
        d = births.dims
        if n != 2 * d:
            raise InputError(f"the birth process's region has {d} position axes, so its objects have the state "
                             f"[p ({d}), v ({d})] of {2 * d} components, but the motion model {motion.name!r} has "
                             f"{n}")
        rng = generator(seed, *key, "births")
        base = len(targets)
        lo, hi = births.region[:, 0], births.region[:, 1]
        counts = rng.poisson(births.rate, (runs, steps))
        counts[:, 0] = 0  # births from the second scan on: the first scan's objects are the listed ones
        total = counts.sum(axis=1)
        if np.any(total > births.max_objects):
            b = int(np.argmax(total > births.max_objects))
            k = int(np.argmax(np.cumsum(counts[b]) > births.max_objects))
            raise InputError(f"the birth process drew {int(total[b])} births in run {b} (the {births.max_objects + 1}"
                             f"-th at scan {k}), more than max_objects = {births.max_objects}: raise max_objects or "
                             f"lower the rate ({births.rate:g} per scan over {steps - 1} scans)")
        for b in range(runs):
            slot = base
            for k in np.repeat(np.arange(steps), counts[b]):
                k = int(k)
                pos = lo + (hi - lo) * rng.random(d)
                vel = births.velocity_mean + births.velocity_std * rng.standard_normal(d)
                life = steps - k
                if births.survival < 1.0:
                    life = min(life, int(rng.geometric(1.0 - births.survival)))  # scans alive, >= 1
                path = sample_motion(np.concatenate([pos, vel])[None], motion, life, rng, t0=float(times[k]))
                states[b, k:k + life, slot] = path.states[0]
                alive[b, k:k + life, slot] = True
                slot += 1
        p_d[base:] = np.nan if births.p_d is None else births.p_d
        labels.extend(["born"] * births.max_objects)
    return MultiTruth(states, alive, times, p_d, tuple(labels))
