"""Parameters of Monte Carlo localisation: slam2d's defaults and ROS amcl's (ROS 1, as shipped
and with the recovery its documentation suggests), so that both run through one filter."""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, ValidationError, model_validator

from slam2d.config import MAX_BEAMS, MAX_SAMPLES, CommandConfig, Section
from slam2d.localization.base import MCL_PRESETS, register_preset
from slam2d.registry import Choice, validation_error

__all__ = ["LocalizationConfig", "LocalizeConfig", "MclConfig", "amcl_config", "preset"]


class MclConfig(Section):
    """A particle filter over SE(2) on a known map (slam2d.localization.mcl)."""

    # particle set and KLD sampling (Fox 2003)
    min_particles: int = Field(100, gt=0, le=MAX_SAMPLES, description="KLD's lower bound")
    max_particles: int = Field(20000, gt=0, le=MAX_SAMPLES, description="KLD's upper bound; the global set")
    kld_err: float = Field(0.02, gt=0, description="epsilon: KL distance bound between sample and true posterior")
    kld_delta: float = Field(0.01, gt=0, lt=1, description="delta: the bound holds with probability 1 - delta")
    kld_bin_xy: float = Field(0.5, gt=0, description="m, histogram bin of KLD sampling and of the clusters")
    kld_bin_theta: float = Field(math.radians(10.0), gt=0, description="rad")
    kld_single_bin: Literal["min", "max"] = Field("min", description="particles when all fall in one bin "
                                                  "(amcl: max)")
    global_candidates: int = Field(5, gt=0, le=1000, description="global localisation: uniform poses weighed by the "
                                   "first scan, in multiples of max_particles, of which max_particles are kept")
    # update and resampling triggers
    update_min_d: float = Field(0.1, ge=0, description="m travelled (odometry) before a filter update")
    update_min_a: float = Field(0.1, ge=0, description="rad turned (odometry) before a filter update")
    resample_ess: float = Field(0.5, ge=0, le=1, description="resample when N_eff < this x N (0: use the interval)")
    resample_interval: int = Field(1, gt=0, description="with resample_ess 0: resample every n-th update")
    # augmented MCL (Thrun et al. 2005, Table 8.3)
    alpha_slow: float = Field(0.001, ge=0, le=1, description="long-term average likelihood decay (0: off)")
    alpha_fast: float = Field(0.1, ge=0, le=1, description="short-term average likelihood decay (0: off)")
    recovery_best_beams: float = Field(0.5, gt=0, le=1, description="while the pose is certain, the recovery "
                                       "is judged on this share of the beams, the best-fitting at each particle: "
                                       "a map lacking part of what the laser sees (an opened door, glass, a wall "
                                       "worn off a SLAM grid) is no kidnapping (1: every beam always, as amcl)")
    recovery_candidates: int = Field(20, gt=0, le=1000, description="random particles are drawn by the scan's "
                                     "likelihood from this many times as many uniform poses (1: uniform, as amcl)")
    hypothesis_fit: bool = Field(True, description="each cluster's total weight follows the scan's likelihood at "
                                 "its weighted mean pose, not the mean over its particles: a look-alike place "
                                 "weighs as much as the true one whatever the number and spread of its particles "
                                 "(False: plain MCL, as amcl)")
    free_clearance: float = Field(0.1, ge=0, description="m from walls of random and global particles")
    # hypotheses and the filter's state (tracking / ambiguous / lost)
    hypotheses: bool = Field(True, description="the state is 'tracking' only once the heaviest compact cluster's "
                             "evidence over the runner-up reaches the map's threshold (confidence) and its "
                             "look-alike places (lookalike_*) were tested; hypotheses keep hypothesis_particles at "
                             "resampling (False: tracking whenever a cluster holds 90 % within converged_sd, as amcl)")
    confidence: float = Field(0.99, gt=0, lt=1, description="tracking needs the best hypothesis's weight over the "
                              "runner-up's to reach places x confidence / (1 - confidence), places being the most "
                              "places of the map that look alike (lookalike analysis; 1 without look-alikes)")
    hypothesis_particles: int = Field(100, ge=0, le=MAX_SAMPLES, description="particles each hypothesis keeps at "
                                      "resampling (with its weight) while it holds hypothesis_keep of the best's")
    hypothesis_keep: float = Field(1e-6, gt=0, le=1, description="weight relative to the best hypothesis below "
                                   "which a hypothesis is left to resampling (1e-6: 13.8 nats, beyond a claim's "
                                   "threshold and the swing of a few updates)")
    lookalike_radius: float = Field(4.0, gt=0, description="m: two places look alike when the walls within this "
                                    "distance match (turns by 90° multiples and shifts)")
    lookalike_match: float = Field(0.8, gt=0, le=1, description="share of those walls that must land on walls "
                                   "(both ways)")
    # odometry motion model (sample_motion_model_odometry)
    alpha1: float = Field(0.05, ge=0, description="rotation noise from rotation")
    alpha2: float = Field(0.01, ge=0, description="rotation noise from translation, rad^2/m^2")
    alpha3: float = Field(0.05, ge=0, description="translation noise from translation")
    alpha4: float = Field(0.01, ge=0, description="translation noise from rotation, m^2/rad^2")
    # sensor model
    model: Literal["likelihood_field", "beam"] = "likelihood_field"
    beams: int = Field(60, gt=0, le=MAX_BEAMS, description="beams used per scan, evenly spread over the valid ones")
    z_hit: float = Field(0.95, ge=0)
    z_rand: float = Field(0.05, ge=0)
    z_short: float = Field(0.1, ge=0, description="beam model only")
    z_max: float = Field(0.05, ge=0, description="beam model only")
    lambda_short: float = Field(0.1, gt=0, description="beam model only, 1/m")
    sigma_hit: float = Field(0.1, gt=0, description="m")
    sigma_hit_uncertain: float = Field(0.3, gt=0, description="m, likelihood field's sigma while the pose is "
                                       "uncertain (no cluster holding 90 % of the weight within converged_sd)")
    converged_sd: float = Field(0.3, gt=0, description="m")
    max_dist: float = Field(2.0, gt=0, description="m, distance transform cap of the likelihood field")
    combine: Literal["product", "amcl"] = Field("product", description="beam likelihoods multiplied (each raised "
                                                "to beam_weight), or amcl's 1 + sum of cubes")
    beam_weight: float = Field(0.2, gt=0, le=1, description="exponent of each beam's likelihood (beams are "
                                "correlated: 1 overstates the evidence)")
    beam_skip: float = Field(0.3, ge=0, lt=1, description="while the pose is certain, a beam counts only if more "
                             "than this share of the particles end it within beam_skip_distance of a wall (amcl's "
                             "beam skipping: what the map lacks pulls no particle); 0: off")
    beam_skip_distance: float = Field(0.5, gt=0, description="m, see beam_skip")
    wall_poses: bool = Field(False, description="score poses inside occupied cells as any other (amcl); False: "
                             "as if every beam missed by the most (a robot cannot stand in a wall)")
    # initial pose of tracking
    initial_sd_xy: float = Field(0.5, ge=0, description="m, standard deviation around an initial pose")
    initial_sd_theta: float = Field(math.pi / 12, ge=0, description="rad")


def amcl_config(recovery: bool = False) -> MclConfig:
    """ROS 1 amcl's defaults (``recovery_alpha_slow`` / ``_fast`` 0 as shipped, or 0.001 / 0.1 suggested)."""
    return MclConfig(
        min_particles=100, max_particles=5000, kld_err=0.01, kld_delta=_delta_of_z(0.99), kld_bin_xy=0.5,
        kld_bin_theta=math.radians(10.0), kld_single_bin="max", update_min_d=0.2, update_min_a=math.pi / 6,
        resample_ess=0.0, resample_interval=2, alpha_slow=0.001 if recovery else 0.0,
        alpha_fast=0.1 if recovery else 0.0, free_clearance=0.0, alpha1=0.2, alpha2=0.2, alpha3=0.2, alpha4=0.2,
        model="likelihood_field", beams=30, z_hit=0.95, z_rand=0.05, sigma_hit=0.2, sigma_hit_uncertain=0.2,
        max_dist=2.0, combine="amcl", wall_poses=True, hypothesis_fit=False, hypotheses=False,
        beam_weight=1.0, beam_skip=0.0, global_candidates=1, recovery_candidates=1, recovery_best_beams=1.0,
        initial_sd_xy=0.5, initial_sd_theta=math.pi / 12,
    )  # fmt: skip


def _delta_of_z(z: float) -> float:
    """delta whose upper (1 - delta) normal quantile is ``z`` (amcl passes kld_z = 0.99 as that quantile)."""
    return 0.5 * math.erfc(z / math.sqrt(2.0))


@register_preset("slam2d")
def slam2d_preset() -> MclConfig:
    """slam2d's defaults: augmented MCL with its recovery, KLD sampling, the likelihood field."""
    return MclConfig()


@register_preset("amcl")
def amcl_preset() -> MclConfig:
    """ROS 1 amcl's defaults as shipped (recovery off)."""
    return amcl_config(False)


@register_preset("amcl_recovery")
def amcl_recovery_preset() -> MclConfig:
    """ROS 1 amcl's defaults with the recovery its documentation suggests."""
    return amcl_config(True)


def preset(name: str) -> MclConfig:
    """The parameters named ``name`` (``MCL_PRESETS``): slam2d, amcl (shipped) or amcl_recovery."""
    return MCL_PRESETS.create(name)


class LocalizationConfig(Section):
    """What is localised and how: the scan stream (the simulated robot or a log) and the filter's parameters."""

    mode: Literal["global", "tracking"] = Field("global", description="no initial pose, or a rough one")
    initial_pose: tuple[float, float, float] | None = Field(
        None, description="tracking: x, y (m), heading (rad); None: the first true (or reference) pose")
    preset: Annotated[str, Choice("mcl_presets")] = Field(
        "slam2d", description="parameters the 'mcl' keys start from: slam2d's, or ROS amcl's (recovery off / on)")
    mcl: dict = Field(default_factory=dict, description="filter parameters over the preset (MclConfig keys)")
    world: str | None = Field(None, description="simulated world: 'office' or a floor-plan PNG; None: the map")
    seconds: float = Field(60.0, gt=0, description="s of simulated driving")
    kidnap: list[float] = Field(default_factory=list, description="s: times the simulated robot is teleported")
    min_jump: float = Field(5.0, ge=0, description="m, shortest teleport")
    snapshots: list[float] = Field(default_factory=list, description="s from the start: particle-cloud figures "
                                   "(empty: the first update, converging, converged, after each kidnap)")
    reference: str | None = Field(None, description="log runs: TUM reference (default: trajectory.tum beside "
                                  "the map)")
    max_scans: int | None = Field(None, gt=0, description="log runs: stop after this many scans")

    def filter_config(self) -> MclConfig:
        """The preset with the ``mcl`` keys over it (an InputError names an unknown or bad key)."""
        try:
            return MclConfig.model_validate({**preset(self.preset).model_dump(), **self.mcl})
        except ValidationError as err:
            raise validation_error(err, "localization.mcl", model=MclConfig) from None


class LocalizeConfig(CommandConfig):
    """``slam2d localize``: the map (a file, or ``office``), the scan log (or the simulated robot) and the
    ``localization`` section. The section's keys are also accepted at the top level (``--set preset=amcl``,
    a flat localize YAML), as is ``figures`` (``output.figures``)."""

    dataset: str | None = Field(None, description="experiment YAML whose dataset section is the scan log "
                                "(None: the simulated robot wandering the map's world)")
    localization: LocalizationConfig = LocalizationConfig()

    @model_validator(mode="before")
    @classmethod
    def _short_keys(cls, data):
        """Top-level keys of the ``localization`` section moved into it; ``figures`` into ``output``."""
        if not isinstance(data, dict):
            return data
        data = dict(data)
        _move(data, "localization", set(LocalizationConfig.model_fields))
        _move(data, "output", {"figures"})
        return data

    def filter_config(self) -> MclConfig:
        """The filter's parameters (:meth:`LocalizationConfig.filter_config`)."""
        return self.localization.filter_config()


def _move(data: dict, section: str, keys: set[str]) -> None:
    """Move the top-level ``keys`` of ``data`` into its mapping ``section`` (a given key wins over the section's);
    a section that is not a mapping is left for validation to report."""
    given = {k: data[k] for k in keys & set(data)}
    if given and isinstance(data.get(section, {}), dict):
        data[section] = {**data.get(section, {}), **given}
        for k in given:
            del data[k]
