"""The built-in exploration strategies: Yamauchi's nearest frontier, explore_lite's frontier cost, and
Li et al.'s candidates (nearest, farthest, utility). Their parameters are keys of the ``exploration``
section (``potential_scale``, ``gain_scale``, ``fallback_frontiers``, ``k1``, ``k2``, ``distance``)."""

from __future__ import annotations

from slam2d.exploration.base import register_strategy


@register_strategy("nearest_frontier")
class NearestFrontier:
    """Yamauchi's: the frontier region nearest along the grid path."""

    def choose(self, explorer, pose, view, distance):
        return explorer.frontier_goal(pose, view, distance)


@register_strategy("explore_lite")
class ExploreLite:
    """explore_lite's: the frontier of lowest potential_scale · distance − gain_scale · size."""

    def choose(self, explorer, pose, view, distance):
        cfg, res = explorer.cfg, view.resolution

        def cost(f):
            return cfg.potential_scale * f.min_distance * res - cfg.gain_scale * f.size * res

        return explorer.frontier_goal(pose, view, distance, cost)


class _Candidate:
    """Li et al.'s candidate nearest (``nearest``) or farthest by grid path; with none left the nearest
    frontier if ``fallback_frontiers``."""

    nearest = True

    def choose(self, explorer, pose, view, distance):
        goal = explorer.candidate_goal(pose, view, distance, self.nearest)
        if goal is None and explorer.cfg.fallback_frontiers:
            goal = explorer.frontier_goal(pose, view, distance)
            explorer.fallbacks += goal is not None
        return goal


@register_strategy("nearest_candidate")
class NearestCandidate(_Candidate):
    """Li et al.'s candidate nearest by grid path (then the nearest frontier, with fallback_frontiers)."""


@register_strategy("farthest_candidate")
class FarthestCandidate(_Candidate):
    """Li et al.'s candidate farthest by grid path (then the nearest frontier, with fallback_frontiers)."""

    nearest = False


@register_strategy("utility")
class Utility:
    """Li et al.'s utility A · exp(−(k1 L + k2 γ)) over the candidates and the frontier regions' goals."""

    def choose(self, explorer, pose, view, distance):
        return explorer.utility_goal(pose, view, distance)


@register_strategy("tour")
class Tour:
    """TARE's and FUEL's: a global tour (OR-tools) over the subspaces holding frontier, viewpoints covering the
    first one's frontier cells (greedy set cover) ordered into a local tour joining it; refined each decision."""

    def __init__(self):
        from slam2d.exploration.tour import TourPlanner

        self.planner = TourPlanner()

    def choose(self, explorer, pose, view, distance):
        return self.planner.choose(explorer, pose, view, distance)
