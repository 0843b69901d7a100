"""Object keyframes and their matching: loop-closure detection (paper 3.2, eq. 2-5)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from neoslam.config.base import Section

__all__ = ["KeyframeConfig", "MatchingConfig", "TRIANGLE_SIDE_BITS"]


class KeyframeConfig(Section):
    """Object keyframes (paper 3.2): the current object and the objects around it, in the world frame.

    Observations are first fused over a short stretch of road (the local window), where odometry drift is small,
    so that a keyframe's object centres average many stereo measurements.
    """

    e_max: float = Field(1.5, gt=0, le=1000, description="e_max of eq. 2, m (paper)")
    neighbourhood_radius: float = Field(
        30.0, gt=0, le=1000, description="objects this close to the current object join its keyframe, m (paper: e_max)"
    )
    sparse_objects: int = Field(
        5,
        gt=0,
        le=1000,
        description="where fewer objects stand within neighbourhood_radius (a sparse street), the neighbourhood "
        "grows until it holds this many (5: chosen over 6, 8 and no growth with benchmarks.loops)",
    )
    sparse_neighbourhood_radius: float = Field(
        60.0, gt=0, le=1000, description="the largest the neighbourhood grows to on a sparse street, m"
    )
    spacing: float = Field(5.0, ge=0.01, le=1e4, description="a keyframe every this many metres of travel")
    min_objects: int = Field(4, gt=0, le=1000, description="fewer objects in the neighbourhood make no keyframe")
    window_length: float = Field(60.0, gt=0, le=1e4, description="observations fused over this much recent travel, m")
    association_radius: float = Field(
        2.5, gt=0, le=1000, description="an observation joins a window object this close, m"
    )
    min_observations: int = Field(3, gt=0, le=1_000_000, description="window objects seen fewer times are left out")
    footprints: dict[str, tuple[float, float]] = Field(
        default_factory=lambda: {"car": (4.3, 1.8), "truck": (8.0, 2.5), "bicycle": (1.8, 0.6), "person": (0.6, 0.6)},
        description="typical length and width of each class, m, lying along the road: stereo points lie on the "
        "visible surface, and the centre is half the footprint further along the viewing ray",
    )
    depth_sigma_at_1m: float = Field(
        0.0007,
        gt=0,
        le=1,
        description="stereo depth std at 1 m, m; grows with depth^2, weights the fusion and gives the keyframe "
        "objects' covariances (0.27 px of disparity at KITTI's focal length x baseline, 380 px m: a margin over the "
        "real front end's fitted disparity noise)",
    )
    bearing_sigma: float = Field(
        0.002,
        gt=0,
        le=1,
        description="std of a view's bearing to an object's centre, rad (about 1.5 px at KITTI's focal length): with "
        "the depth std it gives each keyframe object's covariance, which the matching's tolerances follow",
    )

    @field_validator("footprints")
    @classmethod
    def _footprints_in_metres(cls, footprints: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for label, (length, width) in footprints.items():
            if not (0 <= length <= 100 and 0 <= width <= 100):
                raise ValueError(f"{label}: length and width must lie in [0, 100] m, got ({length}, {width})")
        return footprints


TRIANGLE_SIDE_BITS = 8  # loop.triangles packs each side's bin into this many bits of a key


class MatchingConfig(Section):
    """Keyframe matching and verification (eq. 2-5)."""

    appearance_rmse_threshold: float = Field(80.0, gt=0, le=1000, description="max patch RMSE, 0-255 grey (paper)")
    score_threshold: float = Field(
        1.0, ge=0, le=1e6, description="a score above this is a loop-closure candidate (paper)"
    )
    min_support: int = Field(2, ge=0, le=1000, description="a match needs this many other matches with consistent e_ij")
    min_inliers: int = Field(4, gt=0, le=1000, description="verified matched objects needed to accept a closure")
    min_inlier_ratio: float = Field(
        0.5, ge=0, le=1, description="and this share of the smaller keyframe's objects (a place, not a pattern)"
    )
    tolerances: Literal["covariance", "fixed"] = Field(
        "covariance",
        description="how far a matched object may lie from where the fit puts it: covariance, by each centre's "
        "covariance from its views (a chi-square gate; far objects are allowed their depth noise, near ones stay "
        "strict; loop.verification); fixed, within inlier_distance and max_fit_residual whatever the distance",
    )
    centre_sigma: float = Field(
        0.25,
        gt=0,
        le=100,
        description="std of a keyframe object's centre that no number of views lowers, m, added to its covariance "
        "in each ground axis: the footprint model that moves a view from the visible surface to the middle, the "
        "odometry's drift within the keyframe's window",
    )
    affinity_sigmas: float = Field(
        2.5,
        gt=0,
        le=100,
        description="with tolerances covariance: the tolerance of eq. 2 widens from e_max to this many stds of "
        "|e_ij - e_i'j'| where the centres' covariances make that larger",
    )
    inlier_probability: float = Field(
        0.99,
        gt=0,
        lt=1,
        description="with tolerances covariance: a matched pair is an inlier of the fit within the chi-square "
        "gate (2 degrees of freedom) that holds a right pair with this probability",
    )
    fit_probability: float = Field(
        0.999,
        gt=0,
        lt=1,
        description="with tolerances covariance: the fit's sum of squared normalised residuals must stay within the "
        "chi-square bound (2k - 3 degrees of freedom) that holds a right fit with this probability",
    )
    max_inlier_distance: float = Field(
        4.0,
        gt=0,
        le=1000,
        description="with tolerances covariance: no matched pair further apart than this under the fit is an "
        "inlier, whatever its covariance, m",
    )
    object_area: float = Field(
        150.0,
        gt=0,
        le=1e6,
        description="with tolerances covariance: street area per object, m² (a parked object every 12 m of a "
        "12 m band): with the label's share, the density of strangers that could fall in a pair's gate by chance",
    )
    contradiction_bits: float = Field(
        4.0, ge=0, le=1000, description="with tolerances covariance: evidence a contradicted object costs, bits"
    )
    out_of_view_contradiction_bits: float = Field(
        1.0,
        ge=0,
        le=1000,
        description="with tolerances covariance: evidence a contradicted object out of the other keyframe's view "
        "(contradiction_view_deg) costs, bits: the other pass may have seen it from a pose between its keyframes' or "
        "missed it at the image's edge",
    )
    min_evidence_bits: float = Field(
        6.0,
        ge=0,
        le=1e4,
        description="with tolerances covariance: a verified match carries at least this much evidence that the two "
        "keyframes show one place, bits (loop.verification)",
    )
    max_fit_residual: float = Field(
        0.6, gt=0, le=1000, description="with tolerances fixed: max RMS residual of the rigid fit, m (ground plane)"
    )
    inlier_distance: float = Field(
        1.2,
        gt=0,
        le=1000,
        description="with tolerances fixed: a match fits the rigid transform within this, m; others are left out of "
        "the fit and its RMS (about 3 σ of a right match seen from the other side)",
    )
    max_contradictions: int = Field(
        4,
        ge=0,
        le=10_000,
        description="reject if under the fit more objects than this stand well inside the other keyframe's ground "
        "and in its view (contradiction_view_deg) with no object of their label near them there: a place driven "
        "again shows the same objects, a street that only shares part of its layout shows others",
    )
    contradiction_radius: float = Field(
        2.5,
        gt=0,
        le=1000,
        description="an object with one of its label this close under the fit is not contradicted, m "
        "(keyframes.association_radius: observations this close are one object)",
    )
    contradiction_margin: float = Field(
        3.0,
        ge=0,
        le=1000,
        description="only objects this far inside the other keyframe's ground count, m: near its edge an object may "
        "fall in one keyframe and not in the other by the noise of its centre",
    )
    contradiction_view_deg: float = Field(
        30.0,
        gt=0,
        le=180,
        description="only contradicted objects within this angle of the heading of one of the robot poses the other "
        "keyframe's objects were seen from count against max_contradictions and cost contradiction_bits, degrees "
        "(the others cost out_of_view_contradiction_bits): the camera's half field of view less a margin for objects "
        "cut off at the image's edge (KITTI's is 41°; 180: any direction)",
    )
    max_place_offset: float = Field(
        3.5,
        gt=0,
        le=1000,
        description="accept only if the fit puts the two robot poses this close, m: the same place is within "
        "evaluation.loop_max_distance (5 m), less the error of the fit's offset",
    )
    max_vertical_offset: float = Field(
        6.0,
        gt=0,
        le=1000,
        description="reject if the fit puts the two robot poses this far apart in height, m: a bridge over a street "
        "is another place (6: just above KITTI ground truth's largest height disagreement at a revisited place)",
    )
    max_yaw_drift_deg: float = Field(
        30.0,
        gt=0,
        le=360,
        description="reject a fit that turns the query's world by more than this, degrees, plus yaw_drift_per_100m: "
        "its rotation is the odometry's heading drift between the two passes, and a nearly point-symmetric layout "
        "can also fit turned by 180°",
    )
    yaw_drift_per_100m: float = Field(
        3.0,
        ge=0,
        le=360,
        description="degrees per 100 m travelled since the stored keyframe, added to max_yaw_drift_deg",
    )
    place_radius: float = Field(
        20.0,
        ge=0,
        le=1000,
        description="a retrieved keyframe is matched as a place: with the stored keyframes of its pass whose robot "
        "poses lie this close to its own, their objects merged (loop.places); 0: the keyframe alone",
    )
    place_cache: int = Field(
        1000,
        ge=1,
        le=1_000_000,
        description="merged places kept for the queries that follow, the least recently matched dropped first: a "
        "drive matches the few dozen places around it again and again, and a place holds about 35 kB",
    )
    recentre_places: bool = Field(
        True,
        description="when a place's fit fails on more than max_contradictions objects in view, match once more the "
        "place around the member nearest to where the fit puts the robot (a place reaches place_radius either side "
        "of its anchor: one anchored at the far end holds objects the query never had in view)",
    )
    query_radius: float = Field(
        10.0,
        ge=0,
        le=1000,
        description="the query is the new keyframe with the keyframes just before it whose robot poses lie this "
        "close to its own, their objects merged, m; 0: the new keyframe alone",
    )
    ambiguity_bits: float = Field(
        8.0,
        ge=0,
        le=1e4,
        description="when two places that the fits put more than consistent_distance apart both verify, the best "
        "must carry this much more evidence, bits, or the keyframe relocalises nowhere (a repeated layout)",
    )
    exclude_recent_distance: float = Field(60.0, ge=0, le=1e6, description="never match keyframes from the last metres")
    search_radius: float = Field(
        15.0, gt=0, le=1e5, description="candidates lie this close to the estimated position, m"
    )
    search_radius_per_metre: float = Field(
        0.1, ge=0, le=10, description="plus this share of the distance travelled since the candidate (odometry drift)"
    )
    drift_radius: float = Field(
        15.0,
        gt=0,
        le=1e5,
        description="with tolerances covariance: how far the odometry may have drifted from a stored keyframe, m, "
        "taken as three stds by the evidence's drift prior (a fit that moves the robot by d costs 4.5 (d / R)² / ln 2 "
        "bits), so a distant look-alike is less likely than a near place; search_radius only bounds the candidates",
    )
    drift_radius_per_metre: float = Field(
        0.1, ge=0, le=10, description="plus this share of the distance travelled since the stored keyframe"
    )
    candidates: int = Field(
        10, gt=0, le=1000, description="best retrieval candidates that are matched in full, as distinct places"
    )
    retrieval: Literal["triangles", "signature"] = Field(
        "triangles",
        description="how the eligible keyframes are ranked: triangles, by the object triangles they share with the "
        "query (geometric hashing, loop.triangles); signature, by a histogram of labels and pairwise distances",
    )
    min_shared_triangles: int = Field(
        1,
        ge=0,
        le=10_000,
        description="with retrieval triangles: a retrieved place is matched only if one of its keyframes shares "
        "this many triangle keys with the query",
    )
    triangle_side_bin: float = Field(
        1.0, gt=0, le=100, description="retrieval triangles: sides are rounded to bins this wide, m"
    )
    triangle_objects: int = Field(
        12,
        ge=3,
        le=40,
        description="retrieval triangles: of this many objects nearest a keyframe's current object (12: 220 triangles)",
    )
    triangle_max_side: float = Field(
        40.0, gt=0, le=500, description="retrieval triangles: none with a side longer than this, m"
    )
    power_iterations: int = Field(
        50,
        gt=0,
        le=10_000,
        description="at most this many products of the power iteration (spectral matching): keyframes of one place "
        "converge well within it; those that need more have no dominant consistent group, which verification rejects",
    )
    power_tolerance: float = Field(
        1e-5,
        gt=0,
        le=1,
        description="the power iteration stops once no entry moves more than this: only the order of the entries "
        "is used, and it is settled long before",
    )
    consecutive: int = Field(
        2, gt=0, le=100, description="accept only when this many consecutive keyframes relocalise consistently"
    )
    consistent_distance: float = Field(
        2.0, gt=0, le=1000, description="consecutive relocalisations put the robot within this of each other, m"
    )
    consistent_yaw_deg: float = Field(5.0, gt=0, le=180, description="and within this yaw, degrees")
    evidence: Literal["keyframe", "run"] = Field(
        "run",
        description="what a closure must show, min_evidence_bits plus log2 of the stored keyframes the query could "
        "have matched: keyframe, each of the consecutive keyframes alone; run, the consecutive keyframes that "
        "relocalise consistently together, each matched object counted once (a keyframe alone then needs "
        "min_evidence_bits; loop.runs)",
    )
    run_keyframes: int = Field(
        8,
        gt=0,
        le=1000,
        description="with evidence run: the evidence of at most this many consecutive keyframes is counted together",
    )
    run_gap: int = Field(
        1,
        ge=0,
        le=10,
        description="with evidence run: a run goes on past this many keyframes that relocalise nowhere (too few "
        "objects seen, or a view hidden by traffic): they show nothing against the place",
    )

    @model_validator(mode="after")
    def _triangle_sides_fit_their_bits(self) -> MatchingConfig:
        bins = self.triangle_max_side / self.triangle_side_bin
        if bins >= 2**TRIANGLE_SIDE_BITS:
            raise ValueError(
                f"triangle_max_side / triangle_side_bin is {bins:.4g} bins; a side's bin is held in "
                f"{TRIANGLE_SIDE_BITS} bits, so at most {2**TRIANGLE_SIDE_BITS - 1} bins fit"
            )
        return self
