"""Online SLAM: the frontends and pose graph fed one scan at a time, with a live occupancy grid."""

from slam2d.slam.keyframe_grid import GridUpdate, KeyframeGrid
from slam2d.slam.online import OnlineSlam

__all__ = ["GridUpdate", "KeyframeGrid", "OnlineSlam"]
