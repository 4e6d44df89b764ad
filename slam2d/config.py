"""Experiment configuration: pydantic models for every section, YAML in and out.

Unknown keys are an error naming the key. ``apply_overrides`` implements the
CLI's ``--set a.b=c``; values are parsed as YAML (``--set mapping.resolution=0.1``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from slam2d.errors import InputError, not_a_file, read_text, short_repr  # noqa: F401 (short_repr: for config users)
from slam2d.plugins import load_plugins, resolve
from slam2d.registry import Choice, check_choices, validation_error


MAX_NAME_BYTES = 200  # a results folder's name; its date and hidden-folder suffixes fit in a file system's 255
MIN_RESOLUTION, MAX_RESOLUTION = 1e-3, 10.0  # m per cell of any grid: 1 mm to 10 m
MAX_BEAMS = 10_000  # beams of a (real or simulated) scan
MAX_SAMPLES = 1_000_000  # particles, queries, candidates: counts of things made and scored one by one

Resolution = Annotated[float, Field(ge=MIN_RESOLUTION, le=MAX_RESOLUTION)]
"""A grid's cell size, m: finite, 1 mm to 10 m."""


class Section(BaseModel):
    """Base of all config sections: unknown keys are rejected, and so are options an implementation
    the section names does not take (:class:`slam2d.registry.Choice`); numbers must be finite."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)

    @model_validator(mode="after")
    def _options_fit(self):
        check_choices(self)
        return self


class LaserModel(Section):
    """Simulated laser: beams spread evenly over the field of view."""

    beams: int = Field(360, gt=0, le=MAX_BEAMS)
    fov_deg: float = Field(360.0, gt=0, le=360)
    range_min: float = Field(0.05, ge=0)
    range_max: float = Field(12.0, gt=0)
    range_noise: float = Field(0.01, ge=0, description="Gaussian range noise std, m")
    dropout: float = Field(0.01, ge=0, le=1, description="probability a beam returns nothing")
    height: float = Field(
        0.25, ge=0, description="m above the floor: the laser sees only the parts of 3D objects crossing this height")


class OdometryNoise(Section):
    """Odometry motion-model noise (Probabilistic Robotics, sample_motion_model_odometry).

    alpha1: rotation from rotation, alpha2: rotation from translation,
    alpha3: translation from translation, alpha4: translation from rotation.
    """

    alpha1: float = Field(0.004, ge=0)
    alpha2: float = Field(0.001, ge=0)
    alpha3: float = Field(0.01, ge=0)
    alpha4: float = Field(0.001, ge=0)


class ObjectSpec(Section):
    """One object with a height in a simulated world (``slam2d.sim.objects3d``): a footprint and a height range."""

    kind: Literal["box", "table", "chair", "shelf"] = Field(
        description="box: one solid block over z; table, chair: four 4 cm legs under a 3 cm top at z[1] "
        "(a chair also has a back); shelf: a board over z between two end panels standing on the floor")
    at: tuple[float, float] = Field(description="x, y of the footprint's centre, m")
    size: tuple[Annotated[float, Field(gt=0, le=100)], Annotated[float, Field(gt=0, le=100)]] = Field(
        description="footprint along x and y, m")
    z: tuple[Annotated[float, Field(ge=0)], Annotated[float, Field(gt=0)]] | None = Field(
        None, description="m, (bottom, top); default: box (0, 0.04), table (0, 0.72), chair (0, 0.45), "
        "shelf board (0.30, 0.34)")

    @model_validator(mode="after")
    def _z_order(self):
        if self.z is not None and not self.z[0] < self.z[1]:
            raise ValueError(f"z must be (bottom, top) with bottom < top, got {self.z}")
        return self


class ObjectsConfig(Section):
    """Objects with heights added to a simulated world (listed, from a file, or scattered by the seed)."""

    file: str | None = Field(None, description="YAML file holding a list of objects (ObjectSpec keys); "
                             "relative paths resolve against SLAM2D_DATA if not found")
    items: list[ObjectSpec] = Field(default_factory=list, description="objects listed here")
    boxes: int = Field(0, ge=0, le=1000, description="low boxes (3-5 cm high, 20-40 cm wide) scattered by the seed")
    tables: int = Field(0, ge=0, le=1000, description="tables (0.8-1.2 x 0.6-0.8 m, 0.72 m high) scattered")
    chairs: int = Field(0, ge=0, le=1000, description="chairs (0.45 m square, seat at 0.45 m) scattered")
    shelves: int = Field(0, ge=0, le=1000, description="shelves (0.8-1.2 x 0.3 m, board at 0.30-0.34 m) scattered")
    along_path: bool = Field(True, description="navigate: scatter near the shortest path from start to goal "
                             "(within `spread`), where the robot meets them; false: anywhere free")
    spread: float = Field(0.6, ge=0, description="m, farthest a scattered object's centre lies from that path")


class SimulatorConfig(Section):
    """The embedded default dataset: a world, a scripted route, a laser, odometry."""

    world: str = Field("office", description="built-in world name, or path to an occupancy PNG")
    resolution: Resolution = Field(0.05, description="m per pixel of a PNG world")
    route: list[tuple[float, float]] | None = Field(
        None, description="waypoints (x, y) in m; None takes the world's scripted route"
    )
    speed: float = Field(0.5, gt=0, description="m/s")
    turn_rate: float = Field(1.0, gt=0, description="rad/s")
    scan_rate: float = Field(5.0, gt=0, description="Hz")
    laser: LaserModel = LaserModel()
    odometry: OdometryNoise = OdometryNoise()
    objects: ObjectsConfig = ObjectsConfig()


class DatasetConfig(Section):
    kind: Annotated[str, Choice("datasets")] = Field(
        "simulator", description="the reader: simulator, rosbag, carmen (or one a plugin registers)")
    path: str | None = Field(None, description="log file; relative paths resolve against SLAM2D_DATA")
    scan_topic: str | None = Field(None, description="rosbag LaserScan topic (default: the only one, or /scan)")
    odom_topic: str | None = Field(None, description="rosbag Odometry topic (default: the only one, or /odom)")
    first_scan: int = Field(
        0, ge=0, description="start at this scan of the log (0-based, before skips); max_scans counts from here")
    max_scans: int | None = Field(None, gt=0, description="stop after this many scans")
    max_skipped: float = Field(
        0.05, ge=0, le=1, description="fraction of the scans that may be unusable (bad lines, stamps, poses, "
        "empty) before the run fails"
    )
    simulator: SimulatorConfig = SimulatorConfig()


class FrontendConfig(Section):
    name: Annotated[str, Choice("frontends", options="options", lazy=True)] = Field(
        "icp", description="registered frontend name (slam2d frontends lists them); checked when the run starts "
        "(a --plugin module may register it)")
    options: dict[str, Any] = Field(
        default_factory=dict, description="the frontend's own parameters, checked against its Config model"
    )


class LoopClosureConfig(Section):
    """Candidate search over the optimised keyframes and scan-to-submap verification."""

    enabled: bool = True
    every_n_keyframes: int = Field(5, gt=0, description="search for loops at every n-th keyframe")
    search_radius: float = Field(8.0, gt=0, description="m; candidates within this distance of the new keyframe")
    min_travel: float = Field(10.0, ge=0, description="m travelled between a candidate and the new keyframe")
    submap_keyframes: int = Field(10, ge=0, description="neighbouring keyframes on each side forming the submap")
    window_xy: float = Field(
        2.0, gt=0, description="m; half-width of the translational search window (the drift it can undo)"
    )
    drift: float = Field(
        0.03, ge=0, description="m of drift allowed per m of graph path between two keyframes: widens window_xy ..."
    )
    max_window_xy: float = Field(30.0, gt=0, description="m; ... and search_radius by as much, up to this window")
    wide_every: int = Field(
        4, ge=0, description="a wide search (all places needing twice window_xy) at every n-th loop search (0: never)"
    )
    window_theta_deg: float = Field(30.0, gt=0, description="half-width of the rotational search window")
    resolution: Resolution = Field(0.05, description="m; finest grid of the correlative matcher")
    min_score: float = Field(
        0.55, ge=0, le=1, description="mean likelihood of scan points on the submap to accept (1 = all on it)"
    )
    max_candidates: int = Field(3, gt=0, le=1000, description="candidates verified per new keyframe")
    ambiguity_distance: float = Field(
        0.5, ge=0, description="m; reject a match with a rival this far from it or farther (0: no check) ..."
    )
    ambiguity_ratio: float = Field(0.9, gt=0, le=1, description="... scoring at least this fraction of its score")
    innovation_gate: float = Field(
        100.0,
        ge=0,
        description="a verified loop is not added when its squared Mahalanobis distance from the graph's estimate "
        "(iSAM2's joint marginal plus the loop's own covariance) exceeds this (0: no gate); far above the 99 % "
        "chi-square quantile (11.3) because the marginals are overconfident after long drift",
    )


class RefineConfig(Section):
    """Dense refinement after the final batch: every pair of keyframes within ``radius`` aligned
    point-to-line from the optimised poses, the pairs that overlap added as factors, the graph solved
    again, ``rounds`` times (``slam2d.backend.refine``)."""

    rounds: int = Field(0, ge=0, le=10, description="refinement rounds (0: none)")
    radius: float = Field(1.0, gt=0, le=5, description="m between keyframes paired for alignment")
    min_overlap: float = Field(0.25, gt=0, le=1, description="share of a scan's points that must find a line")


class BackendConfig(Section):
    name: Annotated[str, Choice("backends")] = Field(
        "pose_graph", description="'pose_graph' optimises with GTSAM; 'none' chains the frontend's deltas "
        "(or a plugin's back end)"
    )
    keyframe_distance: float = Field(0.2, ge=0, description="m travelled before a new keyframe")
    keyframe_angle_deg: float = Field(10.0, ge=0, description="rotation before a new keyframe")
    robust: Literal["none", "huber", "cauchy", "dcs"] = Field("cauchy", description="kernel on loop-closure and landmark factors")
    robust_param: float = Field(2.0, gt=0, description="kernel width (whitened units)")
    gnc: bool = Field(False, description="graduated non-convexity in the final batch optimisation")
    turn_sigma: float = Field(
        0.0, ge=0, le=1, description="heading std (rad) added to each scan's match per rad it turns: a matcher's "
        "systematic error in turns, which its own residuals do not show"
    )
    loop_closure: LoopClosureConfig = LoopClosureConfig()
    refine: RefineConfig = RefineConfig()


class MappingConfig(Section):
    """Log-odds occupancy grid."""

    resolution: Resolution = Field(0.05, description="m per cell")
    log_odds_hit: float = Field(0.85, gt=0)
    log_odds_miss: float = Field(-0.4, lt=0)
    log_odds_min: float = Field(-2.0, lt=0)
    log_odds_max: float = Field(3.5, gt=0)
    max_range: float | None = Field(None, gt=0, description="ignore hits farther than this, m")
    every_nth_scan: int = Field(1, gt=0, description="integrate every n-th scan")
    occupied_thresh: float = Field(0.65, gt=0, lt=1)
    free_thresh: float = Field(0.196, gt=0, lt=1, description="below occupied_thresh")
    layers: list[Annotated[str, Choice("map_layers")]] = Field(
        default_factory=lambda: ["grid"],
        description="layers written to the results folder (the grid always; see slam2d.mapping.layers)",
    )

    @model_validator(mode="after")
    def _thresholds_in_order(self):
        if not self.free_thresh < self.occupied_thresh:
            raise ValueError(f"free_thresh {self.free_thresh} must be below occupied_thresh {self.occupied_thresh}")
        return self


class EvaluationConfig(Section):
    relations: str | None = Field(None, description="relations file (Kümmerle 2009); relative to SLAM2D_DATA")
    relation_tolerance: float = Field(1e-3, gt=0, description="s; a relation stamp must match a scan this closely")
    align: bool = Field(True, description="align the estimate to ground truth (SE(2)) before ATE")
    rpe_delta: float = Field(1.0, gt=0, description="RPE pair spacing, m travelled")


class OutputConfig(Section):
    root: str = Field("results", description="results folders are created under this directory")
    figures: bool = True


class NavigationConfig(Section):
    """``slam2d navigate``: drive the simulated robot in ``dataset.simulator.world`` to a goal."""

    start: tuple[float, float, float] | None = Field(
        None, description="x, y (m), heading (rad); None: the start of the world's route (the office)"
    )
    goal: tuple[float, float] | tuple[float, float, float] | None = Field(
        None, description="x, y (m)[, heading (rad)]; --goal x,y on the command line"
    )
    planner: Annotated[str, Choice("local_planners")] = Field(
        "dwa", description="local planner: dwa (dynamic window) or fsm (the 2016 state machine)")
    slam: bool = Field(True, description="pose and map from online SLAM; false: the true pose and the world's map")
    localization: Annotated[str, Choice("localizers", also=("none",))] = Field(
        "none", description="without slam: 'mcl' drives on Monte Carlo localisation in the world's map "
        "(tracking from a rough start pose, slam2d.localization) instead of the true pose"
    )
    people: int = Field(0, ge=0, le=1000, description="people wandering at random (discs the map does not hold)")
    people_speed: float = Field(0.5, gt=0, description="m/s")
    animation: bool = Field(True, description="an animated GIF of the run in the results folder")
    options: dict[str, Any] = Field(
        default_factory=dict, description="navigator parameters (slam2d.navigation.NavigatorConfig)"
    )


class SessionConfig(Section):
    """A run that goes on from a saved session: a results folder of ``slam2d run`` (its ``session.npz``)."""

    continue_from: str | None = Field(
        None, description="results folder this run continues: its scans follow the saved session's last scan "
        "(the same log, onward); graph, map and trajectory cover both")
    localize_in: str | None = Field(
        None, description="results folder whose map this run starts in, from an unknown pose (found by a global "
        "search of its first scans); the two sessions merge into one graph, map and trajectory")

    @model_validator(mode="after")
    def _one_session(self):
        if self.continue_from is not None and self.localize_in is not None:
            raise ValueError("continue_from and localize_in exclude each other: give one session")
        return self


class ExperimentConfig(Section):
    name: str = Field("sim", description="results folder name: no '/' or '\\', no leading '.'")
    seed: int = Field(0, ge=0, lt=2**63, description="one seed for every random choice")
    parallel: bool = Field(True, description="reader and frontend in a worker process ahead of the back end")
    plugins: list[str] = Field(
        default_factory=list, description="Python files or modules imported first (implementations they register)"
    )
    dataset: DatasetConfig = DatasetConfig()
    frontend: FrontendConfig = FrontendConfig()
    backend: BackendConfig = BackendConfig()
    mapping: MappingConfig = MappingConfig()
    evaluation: EvaluationConfig = EvaluationConfig()
    output: OutputConfig = OutputConfig()
    navigation: NavigationConfig = NavigationConfig()
    session: SessionConfig = SessionConfig()

    @field_validator("name")
    @classmethod
    def _folder_name(cls, name: str) -> str:
        return folder_name(name)


def folder_name(name: str) -> str:
    """``name`` if it can name a results folder, else ValueError (for a pydantic validator)."""
    if not 0 < len(name.encode("utf-8", "surrogatepass")) <= MAX_NAME_BYTES or name.startswith(".") \
            or any(c in name for c in "/\\\0"):
        raise ValueError(f"must be a folder name: 1-{MAX_NAME_BYTES} bytes (UTF-8), no '/', '\\' or NUL, no "
                         "leading '.'")
    return name


class CommandConfig(Section):
    """Base of the configs of ``slam2d segment`` and ``slam2d plan``: a name, a seed, an output section
    and the map they read (a file; a relative path resolves against the working directory, then SLAM2D_DATA)."""

    name: str | None = Field(None, description="results folder name (default: the command, map and method)")
    seed: int = Field(0, ge=0, lt=2**63, description="one seed for every random choice")
    plugins: list[str] = Field(
        default_factory=list, description="Python files or modules imported first (implementations they register)"
    )
    map: str | None = Field(None, description="map file (map.yaml, floor-plan PNG, Moving AI .map)")
    resolution: Resolution | None = Field(None, description="m per pixel of an image map (default 0.05)")
    output: OutputConfig = OutputConfig()

    @field_validator("name")
    @classmethod
    def _folder_name(cls, name: str | None) -> str | None:
        return None if name is None else folder_name(name)


def _format_error(err: ValidationError, source: str, model: type[BaseModel] | None = None) -> InputError:
    """The first error of ``err`` in validating a config read from ``source`` (the one formatter, in the registry)."""
    return validation_error(err, source=source, model=model)


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses a mapping key given twice."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, (str, int, float, bool)) and key in seen:
                raise yaml.constructor.ConstructorError(None, None, f"duplicate key {short_repr(key)}",
                                                        key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep)


def read_yaml(path: Path) -> Any:
    """The YAML document in ``path``: InputError (file:line) if it is not UTF-8 text, malformed or repeats a key."""
    text = read_text(path)
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark else str(path)
        raise InputError(where, f"malformed YAML ({str(getattr(err, 'problem', None) or err)[:200]})") from None


def validate(data: dict[str, Any], source: str = "config", model: type[BaseModel] | None = None):
    """Build a ``model`` (default ExperimentConfig) from a plain dict, with one-line errors. The plugins
    it lists are imported first, so that the names they register are known to its checks."""
    model = model or ExperimentConfig
    plugins = data.get("plugins") if isinstance(data, dict) and "plugins" in model.model_fields else None
    if isinstance(plugins, list) and all(isinstance(p, str) for p in plugins):
        load_plugins(plugins)
    try:
        return model.model_validate(data or {})
    except ValidationError as err:
        raise _format_error(err, source, model) from None


def load_dict(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping from ``path`` (clear error if missing or malformed)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "config file not found")
    data = read_yaml(path)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(path, "a config must be a YAML mapping")
    return data


def set_key(data: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``data['a']['b'] = value`` for ``dotted == 'a.b'``, creating sections."""
    *parents, last = dotted.split(".")
    node = data
    for p in parents:
        child = node.setdefault(p, {})
        if not isinstance(child, dict):
            raise InputError(dotted, f"'{p}' is a value, not a section")
        node = child
    node[last] = value


def parse_override(text: str) -> tuple[str, Any]:
    """Split ``'a.b=value'`` into the key and the YAML-parsed value."""
    if "=" not in text:
        raise InputError(f"--set {text}", "expected KEY=VALUE, e.g. frontend.name=icp")
    key, raw = text.split("=", 1)
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    return key.strip(), value


def load(path: str | Path | None = None, overrides: list[str] | dict[str, Any] = (),
         model: type[BaseModel] | None = None):
    """Load a config from YAML (or defaults when ``path`` is None), then apply overrides;
    ``model``: the config's pydantic model (default ExperimentConfig)."""
    data = load_dict(path) if path else {}
    items = overrides.items() if isinstance(overrides, dict) else map(parse_override, overrides)
    for key, value in items:
        set_key(data, key, value)
    if path and isinstance(data.get("plugins"), list):  # relative plugin files: beside the config
        data["plugins"] = [resolve(p, Path(path).parent) if isinstance(p, str) else p for p in data["plugins"]]
    return validate(data, str(path) if path else "config", model)


def dump(cfg: BaseModel, describe: bool = False) -> str:
    """The fully resolved config as YAML; ``describe``: each key with its description as a comment."""
    if not describe:
        return yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False)
    return "\n".join(_described(cfg, 0)) + "\n"


def _described(cfg: BaseModel, depth: int) -> list[str]:
    """YAML lines of ``cfg``: sections nested, values in flow style (JSON), descriptions as comments."""
    lines, values, pad = [], cfg.model_dump(mode="json"), "  " * depth
    for name, field in type(cfg).model_fields.items():
        note = f"  # {' '.join(field.description.split())}" if field.description else ""
        section = getattr(cfg, name)
        if isinstance(section, BaseModel):
            lines += [f"{pad}{name}:{note}", *_described(section, depth + 1)]
        else:
            lines.append(f"{pad}{name}: {json.dumps(values[name], ensure_ascii=False)}{note}")
    return lines
