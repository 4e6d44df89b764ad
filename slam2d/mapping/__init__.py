"""slam2d.mapping: the occupancy grid and the layers made of it (``mapping.base``)."""

from slam2d.mapping.base import MAP_LAYERS, MapLayer, register_layer  # noqa: F401
