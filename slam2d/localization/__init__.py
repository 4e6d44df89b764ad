"""slam2d.localization: Monte Carlo localisation on a known map (augmented MCL, KLD sampling)."""

from slam2d.localization.base import LOCALIZERS, MCL_PRESETS, register_localizer, register_preset
from slam2d.localization.config import LocalizationConfig, LocalizeConfig, MclConfig, amcl_config, preset
from slam2d.localization.maps import KnownMap
from slam2d.localization.mcl import Estimate, ParticleFilter, kld_limit
from slam2d.localization.navigation import MclPoseSource

__all__ = [
           "LOCALIZERS",
           "MCL_PRESETS",
           "register_localizer",
           "register_preset",
           "Estimate",
           "KnownMap",
           "LocalizationConfig",
           "LocalizeConfig",
           "MclConfig",
           "MclPoseSource",
           "ParticleFilter",
           "amcl_config",
           "kld_limit",
           "preset",
]
