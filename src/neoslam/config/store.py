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
        description="SQLite's synchronous setting for the map file (write-ahead log): full, every committed keyframe "
        "survives a power cut; normal, it survives a killed process, and a power cut may lose the last commits",
    )
    relocalisation_candidates: int = Field(
        20,
        gt=0,
        le=100_000,
        description="until a session has joined the stored map, each keyframe is matched in full against this many "
        "stored places, the best that matching.retrieval ranks over the whole map",
    )
    relocalisation_consecutive: int = Field(
        3,
        gt=0,
        le=100,
        description="a session joins the stored map only when this many consecutive keyframes relocalise in it "
        "consistently: more than matching.consecutive, since a search of the whole map meets more look-alikes",
    )
    relocalisation_evidence: Literal["keyframe", "run"] = Field(
        "run",
        description="what a relocalisation must show, the whole map's evidence (matching.min_evidence_bits plus "
        "log2 of the stored keyframes): keyframe, each of the consecutive keyframes alone; run, the consecutive "
        "keyframes that relocalise consistently together, each matched object counted once (a keyframe alone "
        "then needs matching.min_evidence_bits)",
    )
    relocalisation_run_keyframes: int = Field(
        8,
        gt=0,
        le=1000,
        description="with relocalisation_evidence run: the evidence of at most this many consecutive keyframes is "
        "counted together",
    )
    relocalisation_run_gap: int = Field(
        1,
        ge=0,
        le=10,
        description="with relocalisation_evidence run: a run goes on past this many keyframes that relocalise "
        "nowhere (too few objects seen, or a view hidden by traffic): they show nothing against the place",
    )
