"""What a localiser and a parameter preset are (the Protocols), and both by name.

A localiser gives the navigator its pose on a known map (``navigation.localization``; ``none``:
the true pose). A preset is the set of particle-filter parameters the ``mcl`` keys of a
localisation start from (``localization.preset``).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from slam2d.registry import Registry


class Localizer(Protocol):
    """A ``pose_source`` of :func:`slam2d.navigation.run_navigation`, localising on a known map."""

    def __call__(self, step) -> np.ndarray:
        """The pose (3,) after ``step``'s scan and odometry (a :class:`slam2d.sim.robot.StepResult`)."""
        ...


class MclPreset(Protocol):
    """A named set of particle-filter parameters."""

    def __call__(self):
        """The :class:`slam2d.localization.config.MclConfig` of the preset."""
        ...


LOCALIZERS = Registry("localizers", "localiser", key="navigation.localization",
                      builtins={"mcl": "slam2d.localization.navigation"})
"""The localisers by name: ``create(name, None, known, start, range_max=..., seed=...)`` localises on the
:class:`slam2d.localization.maps.KnownMap` ``known`` from the rough pose ``start`` (3,)."""

MCL_PRESETS = Registry("mcl_presets", "preset", key="localization.preset",
                       builtins=dict.fromkeys(("slam2d", "amcl", "amcl_recovery"), "slam2d.localization.config"))
"""The parameter presets of Monte Carlo localisation by name: ``create(name)`` is the MclConfig."""


def register_localizer(name: str, **kw):
    """Decorator of a :class:`Localizer` class: ``navigation.localization: name``."""
    return LOCALIZERS.register(name, **kw)


def register_preset(name: str, **kw):
    """Decorator of a :class:`MclPreset` function: ``localization.preset: name``."""
    return MCL_PRESETS.register(name, **kw)
