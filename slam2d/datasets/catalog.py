"""The public data files slam2d uses: where each comes from, its size, sha256, licence and purpose.

Sizes and hashes were computed from the copies the test suite reads; each URL
points at the same bytes (same git blob) at a fixed commit of the repository
that publishes them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DataFile:
    """One file of the catalogue; ``name`` is its path under the data root."""

    name: str
    size: int
    sha256: str
    url: str
    licence: str
    purpose: str
    origin: str

    @property
    def group(self) -> str:
        """The folder the file lives in (radish, posegraphs, rooms, movingai)."""
        return self.name.split("/", 1)[0]

    @property
    def source(self) -> str:
        """``owner/repo`` of the publishing repository, or the URL's host."""
        parts = self.url.split("/")
        return "/".join(parts[3:5]) if "githubusercontent" in self.url else parts[2]


LICENCES = {  # as the publishing repository states it
    "INESCTEC/ricoslam": "AGPL-3.0 (LICENSE; package.xml says LGPLv3)",
    "HobbySingh/Graph-SLAM": "none stated",
    "david-m-rosen/SE-Sync": "LGPL-3.0",
    "powei-lin/tiny-solver-rs": "MIT OR Apache-2.0",
    "ipa320/ipa_coverage_planning": "LGPL, academic and non-commercial use (commercial: ask Fraunhofer IPA)",
    "krnbatta/warthog": "GPL-2.0-or-later",
}

ORIGINS = {  # who recorded or made the data the publishing repository redistributes
    "radish": "Freiburg SLAM benchmark (Radish logs), Kümmerle et al. 2009",
    "posegraphs": "2D pose-graph benchmarks (Intel, MIT, CSAIL from Luca Carlone's data sets; Olson's M3500)",
    "rooms": "Bormann et al., ICRA 2016, ipa_room_segmentation test maps",
    "movingai": "Moving AI Lab grid benchmarks, Sturtevant 2012",
}

PURPOSES = (  # (group, name ending, purpose): the first match wins
    ("radish", ".bag", "laser log (ROS 1 bag): slam2d run experiments/*.yaml, tests, benchmarks"),
    ("radish", ".clf", "laser log (CARMEN): slam2d run experiments/csail.yaml, tests"),
    ("radish", ".relations", "ground-truth relations: the relations metric (evaluation.relations)"),
    ("posegraphs", ".g2o", "pose-graph benchmark: slam2d optimize, backend tests"),
    ("rooms", "_gt_segmentation.png", "ground-truth rooms: segmentation precision / recall"),
    ("rooms", "_furnitures.png", "furnished floor plan: slam2d segment, segmentation benchmarks"),
    ("rooms", ".png", "floor plan: slam2d segment, navigation and mapping benchmarks"),
    ("movingai", ".scen", "planning scenarios with optimal lengths: planner tests, benchmarks"),
    ("movingai", ".map", "grid map: slam2d plan, A* / HPA* tests and benchmarks"),
)

_FILES = (  # name under the data root, size (bytes), sha256, URL
    ("movingai/16room_000.map", 262693, "efe1156993b2b96df1b23ce4f0f89d4c66b77051d9484efefa93899b141458af", "https://raw.githubusercontent.com/krnbatta/warthog/94acadf685a9e927c43d39aa1e215ca8e56b5089/warthog/maps/rooms/16room_000.map"),
    ("movingai/16room_000.map.scen", 112044, "f15b882d7fbddc666aac82039fa69807fcb1dca4fd3ac4a810e70a1f31afb7ac", "https://raw.githubusercontent.com/krnbatta/warthog/94acadf685a9e927c43d39aa1e215ca8e56b5089/warthog/scenarios/movingai/rooms/16room_000.map.scen"),
    ("movingai/arena.map", 2485, "9887c3022fb76d8e2b49db4a54641e31df79607cf96c2a0ec362702808113d4d", "https://raw.githubusercontent.com/krnbatta/warthog/94acadf685a9e927c43d39aa1e215ca8e56b5089/polyanya/utils/maps/arena.map"),
    ("movingai/arena.map.scen", 7269, "b631475cd551e2e5bb6d4585131197c13be27fcea18a19deb03c1ebf9fce2fc8", "https://raw.githubusercontent.com/krnbatta/warthog/94acadf685a9e927c43d39aa1e215ca8e56b5089/polyanya/scenarios/arena.scen"),
    ("movingai/den312d.map", 5381, "1b3d72a358329a9a37d0aed62ad2668ee7882c4c745c73dc8b4f5d75493c79c4", "https://raw.githubusercontent.com/krnbatta/warthog/94acadf685a9e927c43d39aa1e215ca8e56b5089/warthog/maps/dao/den312d.map"),
    ("movingai/den312d.map.scen", 15732, "1018ffb43c265b2faa946eb7cff41c6541d82ae3cfddf38f1e6326c01e42a188", "https://raw.githubusercontent.com/krnbatta/warthog/94acadf685a9e927c43d39aa1e215ca8e56b5089/warthog/scenarios/movingai/dao/den312d.map.scen"),
    ("posegraphs/CSAIL.g2o", 127618, "66d99ac857a9849d814d214a9ebd0d4876d5d40f0a37be9330c1ff6e6e9daaa6", "https://raw.githubusercontent.com/david-m-rosen/SE-Sync/9b631b6b82d8aa7d32ab846412ae1c070412b7b6/data/CSAIL.g2o"),
    ("posegraphs/M3500.g2o", 727872, "1883593980e602b11bd0ba95799c969e59ee8a6892bdb2a3a48f495459efe9d8", "https://raw.githubusercontent.com/powei-lin/tiny-solver-rs/127ed317220fb0e996d9f0383ae1fcf2526a3cbf/tests/data/input_M3500_g2o.g2o"),
    ("posegraphs/MIT.g2o", 121424, "e5922be0d0689c7a5bc04c58adf3a8e697e240bdd7691cc4218470eaf92956eb", "https://raw.githubusercontent.com/HobbySingh/Graph-SLAM/dc2a2c15f6c164d90b3782dd82a35bae2a15cee3/2d_lidar_slam/data/input_MITb_g2o.g2o"),
    ("posegraphs/intel.g2o", 307525, "3e0724c048e0ba524be9dd268a8b78e19a2497043143584cbb61310638b15c4b", "https://raw.githubusercontent.com/david-m-rosen/SE-Sync/9b631b6b82d8aa7d32ab846412ae1c070412b7b6/data/intel.g2o"),
    ("radish/aces.bag", 1384924, "2854fdb97574583e5d407cdb587c53bb59aa819ba75fe75ac3ee7d08a7d0e8f9", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/bag/aces.sort.bag"),
    ("radish/aces.relations", 99426, "11a15800a751b6f9413078a021d49c7cda85a768c2a465433b4fae7ef57b03d5", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/data/aces.relations"),
    ("radish/fr-clinic.bag", 2405233, "93c27386ac74563544af8ebc735e36b6a316309237a6c1f889bd7b93eb1afc64", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/bag/fr-clinic_robotlaser.sort.bag"),
    ("radish/fr-clinic.relations", 260314, "583b7bba8c1a3ef1f7ad41221c151534333e71b52f5fc267d5e343c79355300c", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/data/fr-clinic.relations"),
    ("radish/fr079.bag", 2241447, "2568336ad52475bfa90ab24750d54a4c2ee7e38f7ec20d076a8b4501b41e92d7", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/bag/fr079.sort.bag"),
    ("radish/fr079.relations", 133044, "7e7f06b4aca455cb68f1f23d04e7c7316c5e17773e872734c860ed7a274cdfc7", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/data/fr079.relations"),
    ("radish/intel.bag", 3978674, "b0de0fd81ee699cecd050fbd4e5611a269b97975163e7e299a82f7bc480db818", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/bag/intel.sort.bag"),
    ("radish/intel.relations", 265713, "330378f153eeae652d6756c1746f335801f66c3e097d90611548e6c4f593c359", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/data/intel.relations"),
    ("radish/mit-csail.clf", 3843167, "f40f31cf9e561cb2a0cb0ca2f4a809abb319543cd1b2875f6c8c6a0138559ca4", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/data/mit-csail.clf"),
    ("radish/mit-csail.relations", 98468, "ffd7ebe97fa1738913931e39ca643ee0a1b67de80499b0197a3d01abad0f589d", "https://raw.githubusercontent.com/INESCTEC/ricoslam/52bfaa91c8e5e56f119265d409b1692ca29d48d2/inesctec_mrdt_slam_2d_datasets/data/mit-csail.relations"),
    ("rooms/Freiburg52_scan.png", 3106, "54a53f47a79ca4501bb994435e7b600c01fd098fcdf94b6b1ca6201dda86c63d", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/Freiburg52_scan.png"),
    ("rooms/Freiburg52_scan_furnitures.png", 11589, "e9afbbddafabe88b59822522532c0a1c22acee3344ccbb76c835ddd7b8f9a7b3", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/Freiburg52_scan_furnitures.png"),
    ("rooms/Freiburg52_scan_gt_segmentation.png", 6123, "1b57f0c7d8503420638feb86773a040c14e394b05978ef0e2307960efcbe9ba9", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/Freiburg52_scan_gt_segmentation.png"),
    ("rooms/Freiburg79_scan.png", 4146, "fb51360bce67938c2562c1a60a774ab9e1aebc558d734afc0fe453d15774ca02", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/Freiburg79_scan.png"),
    ("rooms/Freiburg79_scan_furnitures.png", 13116, "9acb62371f70c9a5c8f39f033aff9b112d69b55b3362d986a1a209f5ff682e6a", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/Freiburg79_scan_furnitures.png"),
    ("rooms/Freiburg79_scan_gt_segmentation.png", 6233, "30893d5a081c8a5d0446d52d7f01833cb8de51ba603133a74b274a7631a31cb3", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/Freiburg79_scan_gt_segmentation.png"),
    ("rooms/lab_b_scan.png", 8374, "e872cb57dc43c92227d687aa4b2babb4f4e21530f55580f9f2384cc69a33be11", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_b_scan.png"),
    ("rooms/lab_b_scan_furnitures.png", 26908, "3f9bd56f795c5a2c926ac6c5f55c18bdc5d16c895bd9bca58feae32989a8ca2b", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_b_scan_furnitures.png"),
    ("rooms/lab_b_scan_gt_segmentation.png", 8211, "ef3b0ecfd440c0c39e464669f97de5ad104d16cd64fd33387aff32eafa1b0170", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_b_scan_gt_segmentation.png"),
    ("rooms/lab_c_scan.png", 3488, "f1035e24d3522b8b7b4e8131953f067bd2670b9d69af07b7b7e10b8a78627724", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_c_scan.png"),
    ("rooms/lab_c_scan_furnitures.png", 16806, "72f46048306f34befd25df3bcaa6e427ec99576d4d93da530e0f1a723bd6d5b2", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_c_scan_furnitures.png"),
    ("rooms/lab_c_scan_gt_segmentation.png", 6222, "c2e3e12a02a93c9f3a3f4e1cdba6570fabca81844ca5b81f8fbdc791e5f8ef98", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_c_scan_gt_segmentation.png"),
    ("rooms/lab_d_scan.png", 4866, "a5d3ef73f782411c36c5b0e886033ad85a3da940d4501a2961bd0d03c7b34f3c", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_d_scan.png"),
    ("rooms/lab_d_scan_furnitures.png", 12350, "e9bc7db3c0789353b34a1e31e1de1776eed52537701ab92f6737aa74bea2134a", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_d_scan_furnitures.png"),
    ("rooms/lab_d_scan_gt_segmentation.png", 6932, "5032a1efc7d545555dfc9f743a14bb4ffd2e8adb165a08726d7448cbfa602ff9", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_d_scan_gt_segmentation.png"),
    ("rooms/lab_ipa.png", 6911, "1d3056e14cc2f825b80a268fb38e3def4720aa647d1158d8e90b9db2cee5ce20", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_ipa.png"),
    ("rooms/lab_ipa_furnitures.png", 18712, "fc68dfb64ea8227de6343fbceeea30e59c11428509971f29b68fe680715841c6", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_ipa_furnitures.png"),
    ("rooms/lab_ipa_gt_segmentation.png", 6585, "7a43c709654889d8e8c04c0170e31b2263459e19498eac5fa819c8e4fc63e34c", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/lab_ipa_gt_segmentation.png"),
    ("rooms/office_a.png", 28121, "ea1df884db7a8bf2802043c8d1c6ac65bf08b47ec1f08c487012047b1cf29c1d", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_a.png"),
    ("rooms/office_a_furnitures.png", 67194, "94e63d3f8b8dc57b2c97c3ff5b789abcde8ec45d2fa42dcf40744b67b1d94786", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_a_furnitures.png"),
    ("rooms/office_a_gt_segmentation.png", 30187, "47570a36558c3b1fb66cb6df8dfe737e6654b5c212c29873575f77b945e56ec7", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_a_gt_segmentation.png"),
    ("rooms/office_b.png", 7688, "8536ab6202b43d3266f6588772fdb322134bcea270b6e5c87f988ce4cebf70de", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_b.png"),
    ("rooms/office_b_furnitures.png", 48409, "0aac0705035fce0f972bcdd4204adc382b8f1c6bf92a9260ae002370ab7cc1fa", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_b_furnitures.png"),
    ("rooms/office_b_gt_segmentation.png", 20900, "a791b7cfd077e05c68fa1868fb75273be4c0921906ae4af7c105239d5b3934c2", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_b_gt_segmentation.png"),
    ("rooms/office_c.png", 27132, "2b9585330c6814ee3f5bfe8df617431fdd853e796c0cf47e384a5ad8c9377066", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_c.png"),
    ("rooms/office_c_furnitures.png", 92602, "87840d4dadc49a7975125df5bbf1e9decd180234724bbcdf81531314aa9a0842", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_c_furnitures.png"),
    ("rooms/office_c_gt_segmentation.png", 67563, "5b65f34addec0b56b0f4504e78c5960ae0918b0b1635a63c18e37ef5216c0bb6", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_c_gt_segmentation.png"),
    ("rooms/office_d.png", 11743, "7a70ce250246f703f2511a734ab7667892a2277167fe64153156b29f31931692", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_d.png"),
    ("rooms/office_d_furnitures.png", 45384, "ef834aecb51b87839650e8171c20e14ae0194f647af443b37ff7376a3b03607e", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_d_furnitures.png"),
    ("rooms/office_d_gt_segmentation.png", 27346, "d0a11a9cea19f54050349917d5a1f5ec5589f0d8e9efe400be6d048e8f0933ce", "https://raw.githubusercontent.com/ipa320/ipa_coverage_planning/f8a1dae4a09693f36a84fd92b6f9772d4c6faff1/ipa_room_segmentation/common/files/test_maps/office_d_gt_segmentation.png"),
)


def _purpose(name: str) -> str:
    group = name.split("/", 1)[0]
    return next(p for g, end, p in PURPOSES if g == group and name.endswith(end))


def _entry(name: str, size: int, sha256: str, url: str) -> DataFile:
    repo = "/".join(url.split("/")[3:5])
    return DataFile(name, size, sha256, url, LICENCES[repo], _purpose(name), ORIGINS[name.split("/", 1)[0]])


CATALOGUE: tuple[DataFile, ...] = tuple(_entry(*row) for row in _FILES)
"""Every data file, sorted by name."""
