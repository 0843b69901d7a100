"""Configuration of raw stereo inputs (a camera's own images, EuRoC recordings): rectification and pairing; part of
the `perception` section as `perception.rectification` and `perception.euroc`."""

from __future__ import annotations

from pydantic import Field

from neoslam.config.base import Section

__all__ = ["RectificationConfig", "EurocConfig"]


class RectificationConfig(Section):
    """Rectifying a raw (distorted, unaligned) stereo pair before the front end sees it."""

    alpha: float = Field(
        0.0,
        ge=0,
        le=1,
        description="free scaling of the rectified images (OpenCV's stereoRectify alpha, the fisheye model's "
        "balance): 0 zooms in until every pixel of the rectified images has a source pixel (no black border), 1 "
        "keeps every source pixel (black borders where the distorted image has none)",
    )


class EurocConfig(Section):
    """Reading a recording in the EuRoC / ASL layout (mav0/cam0, mav0/cam1, optional ground truth)."""

    pair_tolerance_s: float = Field(
        0.001,
        gt=0,
        le=1,
        description="a cam0 and a cam1 image pair when their stamps differ by at most this, s (EuRoC's two cameras "
        "are triggered together and their stamps are equal)",
    )
    skip_unpaired: bool = Field(
        False,
        description="drop images inside the recording without a partner on the other camera instead of stopping "
        "with an error (images before the other camera's first or after its last are always left out)",
    )
    ground_truth_gap_s: float = Field(
        0.02,
        gt=0,
        le=10,
        description="an image's ground-truth pose is interpolated between the ground-truth samples around its stamp, "
        "which must both be this close to it, s (EuRoC's ground truth comes at 200 Hz)",
    )
