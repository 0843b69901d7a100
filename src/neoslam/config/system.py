"""The whole configuration: one section per component."""

from __future__ import annotations

from pydantic import Field

from neoslam.config.base import Section
from neoslam.config.cells import GridCellConfig, HeadDirectionConfig, HebbianConfig, ObjectVectorConfig
from neoslam.config.evaluation import EvaluationConfig
from neoslam.config.live import LiveConfig
from neoslam.config.loop import KeyframeConfig, MatchingConfig
from neoslam.config.mapping import ExperienceMapConfig, MovingObjectsConfig, ObjectMapConfig
from neoslam.config.navigation import NavigationConfig
from neoslam.config.perception import PerceptionConfig
from neoslam.config.sensors import MotionLimitsConfig
from neoslam.config.simulator import SimulatorConfig
from neoslam.config.store import MapStoreConfig

__all__ = ["MAP_SECTIONS", "NeoSLAMConfig"]

# The sections that shape a map (the cells, keyframes, matching and the maps): a map file is extended only with the
# values it was made with (neoslam.store), and a sweep's cells that differ in these alone share one simulation.
MAP_SECTIONS = (
    "grid_cells",
    "head_direction",
    "object_vector",
    "hebbian",
    "keyframes",
    "matching",
    "experience_map",
    "object_map",
    "moving_objects",
)


class NeoSLAMConfig(Section):
    """Everything, one section per component."""

    perception: PerceptionConfig = PerceptionConfig()
    simulator: SimulatorConfig = Field(default_factory=SimulatorConfig)
    grid_cells: GridCellConfig = GridCellConfig()
    head_direction: HeadDirectionConfig = HeadDirectionConfig()
    object_vector: ObjectVectorConfig = ObjectVectorConfig()
    hebbian: HebbianConfig = HebbianConfig()
    keyframes: KeyframeConfig = KeyframeConfig()
    matching: MatchingConfig = MatchingConfig()
    experience_map: ExperienceMapConfig = ExperienceMapConfig()
    object_map: ObjectMapConfig = ObjectMapConfig()
    moving_objects: MovingObjectsConfig = MovingObjectsConfig()
    map_store: MapStoreConfig = MapStoreConfig()
    navigation: NavigationConfig = NavigationConfig()
    evaluation: EvaluationConfig = EvaluationConfig()
    motion_limits: MotionLimitsConfig = MotionLimitsConfig()
    live: LiveConfig = LiveConfig()
