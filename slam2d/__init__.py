"""slam2d: a framework for 2D laser SLAM research."""

__version__ = "0.1.0"
