"""The graph both map back ends correct: nodes are experiences' poses, links are relative poses between them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from neoslam.geometry import invert_pose
from neoslam.types import Link

__all__ = ["MapGraph"]


@dataclass
class MapGraph:
    """Experience poses T_world_robot (n, 4, 4), corrected in place by a back end, and their links."""

    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    links: list[Link] = field(default_factory=list)  # every link ever made: a link keeps its index
    withdrawn: list[int] = field(default_factory=list)  # links taken out again, in the order they were

    def live(self) -> list[int]:
        """Indices of the links in use (all but the withdrawn), in order."""
        if not self.withdrawn:
            return list(range(len(self.links)))
        out = set(self.withdrawn)
        return [index for index in range(len(self.links)) if index not in out]

    def live_links(self) -> list[Link]:
        """The links in use."""
        return [self.links[index] for index in self.live()] if self.withdrawn else self.links

    def __len__(self) -> int:
        return len(self.poses)

    def add_node(self, pose: np.ndarray) -> int:
        self.poses = np.concatenate([self.poses, pose[None]])
        return len(self.poses) - 1

    def add_link(self, link: Link) -> None:
        if not (0 <= link.source < len(self) and 0 <= link.target < len(self)):
            raise IndexError(f"link {link.source} -> {link.target} names a node outside 0..{len(self) - 1}")
        self.links.append(link)

    def link_residuals(self) -> np.ndarray:
        """Per link, the translation (m) between where the target is and where the link puts it."""
        if not self.links:
            return np.zeros(0)
        sources = np.array([link.source for link in self.links])
        targets = np.array([link.target for link in self.links])
        relatives = np.array([link.relative for link in self.links])
        predicted = self.poses[sources] @ relatives
        return np.linalg.norm(predicted[:, :3, 3] - self.poses[targets][:, :3, 3], axis=1)

    def relative(self, source: int, target: int) -> np.ndarray:
        return invert_pose(self.poses[source]) @ self.poses[target]
