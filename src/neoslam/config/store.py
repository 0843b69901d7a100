"""The map file kept over sessions."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from neoslam.config.base import Section

__all__ = ["MapStoreConfig"]


class MapStoreConfig(Section):
    """A map kept in a file over several sessions (`neoslam run --map FILE`, beyond the paper)."""

    synchronous: Literal["full", "normal"] = Field(
        "full",
        description="SQLite's synchronous setting for the map file (write-ahead log): full makes every committed "
        "keyframe survive a power cut too; normal survives a killed process and keeps the file consistent after a "
        "power cut, which may lose the last commits",
    )
    relocalisation_candidates: int = Field(
        20,
        gt=0,
        le=100_000,
        description="until a session has joined the stored map, each keyframe is matched in full against this many "
        "stored places, the best the retrieval (matching.retrieval) ranks over the whole map (its pose relative to "
        "the map is unknown)",
    )
    relocalisation_consecutive: int = Field(
        3,
        gt=0,
        le=100,
        description="a session joins the stored map only when this many consecutive keyframes relocalise in it "
        "consistently (matching.consecutive within a session): a search over the whole map meets more look-alike "
        "places than a drift-bounded one, and a wrong relocalisation is worse than none",
    )
