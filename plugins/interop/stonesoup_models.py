"""Workbench models as Stone Soup models (imported only where Stone Soup is installed).

- :func:`transition_model`: a :class:`~workbench.models.MotionModel` ``(F, Q)`` for one step as Stone Soup's
  ``LinearGaussianTimeInvariantTransitionModel`` (the workbench rebuilds ``F, Q`` for every interval, so the
  Stone Soup model is made per step and its own time interval is not used).
- :func:`measurement_model`: a :class:`~workbench.models.MeasurementModel` (``h``, ``R``, Jacobian or ``H``,
  angular components) as a Stone Soup Gaussian measurement model: :class:`WorkbenchLinearMeasurement` (a
  ``LinearModel`` with ``matrix() = H``) for a linear model, :class:`WorkbenchMeasurement` otherwise.  Angular
  components come out as Stone Soup ``Bearing`` values, so Stone Soup's own innovation and sigma-point mean
  wrap them; the log-likelihood wraps them with the workbench model's ``residual``.  The Jacobian is the
  workbench model's own, or Stone Soup's numerical one for a model without it.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import multivariate_normal

from .stonesoup_available import require_stonesoup

require_stonesoup("workbench_interop.stonesoup_models")  # a named error, not a bare ModuleNotFoundError

from stonesoup.base import Property  # noqa: E402
from stonesoup.models.base import GaussianModel, LinearModel  # noqa: E402
from stonesoup.models.measurement.base import MeasurementModel as StoneSoupMeasurementModel  # noqa: E402
from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel  # noqa: E402
from stonesoup.types.angle import Bearing  # noqa: E402
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors  # noqa: E402

from workbench.models import MeasurementModel, MotionModel

__all__ = ["transition_model", "measurement_model", "WorkbenchMeasurement", "WorkbenchLinearMeasurement",
           "typed_vector"]


def transition_model(motion: MotionModel, rng: np.random.Generator | None = None):
    """Stone Soup's linear-Gaussian transition ``x_k = F x_{k-1} + w``, ``w ~ N(0, Q)``, for one step of ``motion``.

    Its process-noise draws (a particle predictor's) come from ``rng``.
    """
    model = LinearGaussianTimeInvariantTransitionModel(transition_matrix=np.array(motion.F, dtype=float),
                                                       covariance_matrix=CovarianceMatrix(np.array(motion.Q,
                                                                                                   dtype=float)))
    model.random_state = rng
    return model


def typed_vector(z: np.ndarray, angular) -> StateVector | StateVectors:
    """Measurements ``z (m,)`` or ``(m, N)`` as a Stone Soup vector, angular components as ``Bearing``."""
    z = np.asarray(z, dtype=float)
    column = z.ndim == 1
    z = z.reshape(z.shape[0], -1)
    if any(angular):
        out = z.astype(object)
        for i, is_angle in enumerate(angular):
            if is_angle:
                out[i] = [Bearing(v) for v in z[i]]
        z = out
    return StateVector(z) if column else StateVectors(z)


class WorkbenchMeasurement(StoneSoupMeasurementModel, GaussianModel):
    """A workbench :class:`~workbench.models.MeasurementModel` as a Stone Soup Gaussian measurement model:
    ``z = h(x) + v``, ``v ~ N(0, R)``, over the whole state (``mapping`` is every state component)."""

    model: MeasurementModel = Property(doc="The workbench measurement model")
    noise_covar: CovarianceMatrix = Property(doc="Noise covariance R (the model's, or one detection's own)")

    @property
    def ndim_meas(self) -> int:
        return self.model.dim

    def covar(self, **kwargs) -> CovarianceMatrix:
        return CovarianceMatrix(self.noise_covar)

    def _h(self, state) -> np.ndarray:
        x = np.asarray(state.state_vector, dtype=float)  # (n, N)
        return np.asarray(self.model.h(x.T), dtype=float).reshape(x.shape[1], self.model.dim).T  # (m, N)

    def function(self, state, noise=False, **kwargs):
        z = self._h(state)
        if isinstance(noise, bool) or noise is None:
            noise = np.asarray(self.rvs(num_samples=z.shape[1], **kwargs), dtype=float) if noise else 0.0
        z = z + np.asarray(noise, dtype=float).reshape(-1, 1) if np.ndim(noise) == 1 else z + noise
        return typed_vector(z[:, 0], self.model.angular) if z.shape[1] == 1 else typed_vector(z, self.model.angular)

    def jacobian(self, state, **kwargs) -> np.ndarray:
        x = np.asarray(state.state_vector, dtype=float)[:, :1].T  # (1, n)
        if self.model.jacobian is not None:
            return np.array(self.model.jacobian(x)[0], dtype=float)
        if self.model.H is not None:
            return np.array(self.model.H, dtype=float)
        return super().jacobian(state, **kwargs)

    def logpdf(self, state1, state2, **kwargs):
        # log N(z; h(x), R) with the angular components of z - h(x) wrapped to (-pi, pi]
        z = np.asarray(state1.state_vector, dtype=float).reshape(-1)
        nu = self.model.residual(z[None, :], self._h(state2).T)  # (N, m)
        out = np.atleast_1d(multivariate_normal.logpdf(nu, cov=np.asarray(self.covar(), dtype=float)))
        return out[0] if out.size == 1 else out


class WorkbenchLinearMeasurement(WorkbenchMeasurement, LinearModel):
    """A linear workbench measurement model (``h(x) = H x``) as a Stone Soup ``LinearModel``."""

    def matrix(self, **kwargs) -> np.ndarray:
        return np.array(self.model.H, dtype=float)

    def function(self, state, noise=False, **kwargs):
        return WorkbenchMeasurement.function(self, state, noise, **kwargs)

    def jacobian(self, state, **kwargs) -> np.ndarray:
        return self.matrix()


def measurement_model(model: MeasurementModel, ndim_state: int, R=None) -> WorkbenchMeasurement:
    """``model`` as a Stone Soup measurement model of a state of ``ndim_state`` components; ``R`` replaces the
    model's noise covariance (a detection's own)."""
    cls = WorkbenchLinearMeasurement if model.H is not None else WorkbenchMeasurement
    return cls(ndim_state=ndim_state, mapping=tuple(range(ndim_state)), model=model,
               noise_covar=CovarianceMatrix(np.array(model.R if R is None else R, dtype=float)))
