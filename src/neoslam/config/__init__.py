"""Configuration: one pydantic model per component, with the paper's values as documented defaults.

Precedence, lowest first: defaults < YAML file (`--config`) < environment variables
`NEOSLAM_<SECTION>__<FIELD>` (for example `NEOSLAM_EXPERIENCE_MAP__CORRECTION_FACTOR=0.3`).

One module per area: `sensors` (camera, motion limits), `perception` (the real front end), `cells`, `loop`
(keyframes, matching), `mapping`, `store`, `navigation`, `evaluation`; the simulator's settings in `simulator` and
`simulated_world`, its calibration constants (the named detection and odometry noise profiles) in `calibration`;
`system` puts the sections together and `loading` reads them.
"""

from neoslam.config.calibration import DETECTION_PROFILES, NOISE_PROFILES, DetectionProfile
from neoslam.config.cells import GridCellConfig, HeadDirectionConfig, HebbianConfig, ObjectVectorConfig
from neoslam.config.evaluation import EvaluationConfig
from neoslam.config.live import LiveConfig
from neoslam.config.loading import (
    ENV_PREFIX,
    config_values,
    describe_validation_error,
    dump_config,
    load_config,
    merge_settings,
)
from neoslam.config.loop import KeyframeConfig, MatchingConfig
from neoslam.config.mapping import ExperienceMapConfig, MovingObjectsConfig, ObjectMapConfig
from neoslam.config.navigation import NavigationConfig
from neoslam.config.perception import BagConfig, DetectionPass, DetectorConfig, PerceptionConfig
from neoslam.config.sensors import CameraConfig, MotionLimitsConfig
from neoslam.config.simulated_world import DetectionNoiseConfig, OdometryNoiseConfig, WorldConfig
from neoslam.config.simulator import SimulatorConfig
from neoslam.config.store import MapStoreConfig
from neoslam.config.system import MAP_SECTIONS, NeoSLAMConfig

__all__ = [
    "merge_settings",
    "config_values",
    "CameraConfig",
    "WorldConfig",
    "DetectionNoiseConfig",
    "OdometryNoiseConfig",
    "NOISE_PROFILES",
    "DETECTION_PROFILES",
    "DetectionProfile",
    "SimulatorConfig",
    "GridCellConfig",
    "HeadDirectionConfig",
    "ObjectVectorConfig",
    "HebbianConfig",
    "KeyframeConfig",
    "MatchingConfig",
    "ExperienceMapConfig",
    "ObjectMapConfig",
    "MovingObjectsConfig",
    "EvaluationConfig",
    "MotionLimitsConfig",
    "MapStoreConfig",
    "NavigationConfig",
    "LiveConfig",
    "MAP_SECTIONS",
    "PerceptionConfig",
    "DetectorConfig",
    "DetectionPass",
    "BagConfig",
    "NeoSLAMConfig",
    "load_config",
    "dump_config",
    "describe_validation_error",
    "ENV_PREFIX",
]
