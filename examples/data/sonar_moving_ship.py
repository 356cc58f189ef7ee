"""Make ``sonar_moving_ship_synthetic.csv``: a SYNTHETIC active-sonar recording from a moving, turning ship.

What the file shows of the sonar format (docs/recorded-data.md): irregular ping times (a ``time`` column),
the own ship's position and heading on every row, bearings relative to the bow (``#! bearing: relative``), each
detection's own accuracy (``sigma_range``, ``sigma_bearing``) and a ping without detections.  It is not measured
data.

The scene: the own ship starts at the origin heading 30 deg (math convention) at 5 m/s and turns to 120 deg over
pings 25-34; one target moves at about (-3, 1.5) m/s from (3000, 2000) m with white-noise acceleration
(0.02 m/s^2); pings every 2-8 s (uniform); the target is detected with probability 0.9, each detection with its
own range and bearing accuracy (3-8 m, 0.5-1.5 deg, drawn per detection, and its error drawn with exactly that
accuracy); Poisson clutter (mean 3 per ping) uniform in range 200-6000 m and in relative bearing.

``python examples/data/sonar_moving_ship.py`` rewrites the file; :func:`scene` returns the truth beside it
(tests read both).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench import Scans, constant_velocity, generator
from workbench.types import CLUTTER
from workbench.recorded.sonar import OwnShip, write_sonar_csv

FILE = Path(__file__).with_name("sonar_moving_ship_synthetic.csv")
SEED = 20261123
PINGS = 60
SIGMA_A = 0.02
P_D = 0.9
CLUTTER_MEAN = 3.0
HEADER = ("SYNTHETIC: not measured data. A moving, turning own ship, irregular ping times, bearings relative to the "
          "bow, per-detection accuracy; made by examples/data/sonar_moving_ship.py")


@dataclass(frozen=True)
class Scene:
    """The truth behind the file: ``times (T,)``, ``target (T, 4)`` = x, y, vx, vy, the own ship, and the detections
    in x-y with their covariances and origins (0 target, -1 clutter)."""

    times: np.ndarray
    target: np.ndarray
    own_ship: OwnShip
    scans: Scans


def _heading(k: int) -> float:
    return 30.0 + 90.0 * min(max((k - 25) / 10.0, 0.0), 1.0)


def scene(seed: int = SEED) -> Scene:
    rng = generator(seed, "sonar-moving-ship")
    dts = rng.uniform(2.0, 8.0, PINGS - 1)
    times = np.concatenate([[0.0], np.cumsum(dts)]).round(3)
    target = np.empty((PINGS, 4))
    target[0] = (3000.0, 2000.0, -3.0, 1.5)
    for k in range(1, PINGS):
        step = constant_velocity(2, times[k] - times[k - 1], SIGMA_A)
        target[k] = step.F @ target[k - 1] + step.Q_sqrt @ rng.standard_normal(4)
    heading = np.array([_heading(k) for k in range(PINGS)])
    own = np.zeros((PINGS, 2))
    for k in range(1, PINGS):
        h = math.radians(heading[k - 1])
        own[k] = own[k - 1] + 5.0 * (times[k] - times[k - 1]) * np.array([math.cos(h), math.sin(h)])
    rows: list[list[tuple]] = []
    for k in range(PINGS):
        ping = []
        if k != 40 and rng.random() < P_D:  # ping 40: nothing detected, the file keeps the ping
            ping.append((target[k, :2], 0))
        if k != 40:
            for _ in range(rng.poisson(CLUTTER_MEAN)):
                r, b = rng.uniform(200.0, 6000.0), math.radians(heading[k] + rng.uniform(-180.0, 180.0))
                ping.append((own[k] + r * np.array([math.cos(b), math.sin(b)]), CLUTTER))
        rows.append(ping)
    M = max(len(p) for p in rows)
    z = np.zeros((1, PINGS, M, 2))
    cov = np.broadcast_to(np.eye(2), (1, PINGS, M, 2, 2)).copy()
    valid = np.zeros((1, PINGS, M), dtype=bool)
    origin = np.full((1, PINGS, M), CLUTTER)
    for k, ping in enumerate(rows):
        for j, (point, who) in enumerate(ping):
            d = point - own[k]
            r, b = math.hypot(*d), math.atan2(d[1], d[0])
            sr, sb = rng.uniform(3.0, 8.0), math.radians(rng.uniform(0.5, 1.5))
            rm, bm = r + sr * rng.standard_normal(), b + sb * rng.standard_normal()
            z[0, k, j] = own[k] + rm * np.array([math.cos(bm), math.sin(bm)])
            # the detection's x-y covariance, J diag(sr^2, sb^2) J^T at the measured point
            J = np.array([[math.cos(bm), -rm * math.sin(bm)], [math.sin(bm), rm * math.cos(bm)]])
            cov[0, k, j] = J @ np.diag([sr * sr, sb * sb]) @ J.T
            valid[0, k, j], origin[0, k, j] = True, who
    scans = Scans(z, valid, times, origin=origin, cov=cov)
    return Scene(times, target, OwnShip(times, own, heading), scans)


def write(path: Path = FILE, seed: int = SEED) -> Path:
    s = scene(seed)
    return write_sonar_csv(path, s.scans, frame="polar", comments=[HEADER], digits=4, key="time",
                           own_ship=s.own_ship, bearing="relative", accuracy=True)


if __name__ == "__main__":
    print(write())
