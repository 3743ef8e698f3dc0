"""Array and spectrum types shared by the two-body modules."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
#: An isotropic PSD ``C(q)`` [m⁴] of ``q`` [rad/m].
PSD = Callable[[npt.ArrayLike], FloatArray]
