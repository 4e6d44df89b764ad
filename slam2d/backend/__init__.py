"""slam2d.backend: the back ends (``backend.base``) and the pose graph behind them."""

from slam2d.backend.base import BACKENDS, Backend, register_backend  # noqa: F401
