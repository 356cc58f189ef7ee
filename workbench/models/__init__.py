"""Motion and measurement models: what filters need to know about dynamics (:mod:`workbench.models.motion`) and
sensors (:mod:`workbench.models.measurement`).  Everything here is also importable from ``workbench.models``."""

from .measurement import *  # noqa: F401,F403
from .measurement import __all__ as _measurement_all
from .motion import *  # noqa: F401,F403
from .motion import __all__ as _motion_all
from .motion import _lower_factor, model_label  # noqa: F401  (shared by model builders and the kits)

__all__ = list(_motion_all) + list(_measurement_all)
