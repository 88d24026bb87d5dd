"""Column views shared by the in-process and shared-memory haptic logs."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


class HapticColumns:
    """Named columns over ``self._data`` rows [time, position 3, grip, force 3] up to ``self.count``."""

    _data: NDArray[np.float64]
    count: int

    @property
    def time(self) -> NDArray[np.float64]:
        return self._data[: self.count, 0]

    @property
    def position(self) -> NDArray[np.float64]:
        return self._data[: self.count, 1:4]

    @property
    def grip(self) -> NDArray[np.float64]:
        return self._data[: self.count, 4]

    @property
    def force(self) -> NDArray[np.float64]:
        return self._data[: self.count, 5:8]
