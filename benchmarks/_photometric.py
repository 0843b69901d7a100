"""Part (d) of the real_streets study: what each part of a photometric change costs the front end on real frames.

The 51 frames of kitti_06_51 through each change alone (gain and offset, sensor noise, blur, a shift, a darker
exposure) and through the revisit's third-pass change (all of them at once), both images alike, as
`neoslam.datasets.replay` makes them; counted over the frames: the detections of the kept classes, and the objects
placed in 3-D by stereo. Each with the contrast equalisation before detection as configured
(`perception.detector.contrast_clip`, CLAHE) and without it (clip 0). A later session's keyframes need objects
confirmed over several frames, so what a change costs here is what it costs relocalisation on real images.

    python -m benchmarks.real_streets --parts photometric
"""

from __future__ import annotations

from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.datasets.replay import PhotometricChange
from neoslam.perception.frontend import StereoPair, open_front_end

__all__ = ["photometric_rows"]

NOISE_SEED = 1  # the noise of the change alone; the third pass draws its own


def changes(third_pass: PhotometricChange) -> dict[str, PhotometricChange]:
    """Each part of the third pass's change alone, a darker exposure, and the third pass's change whole."""
    return {
        "unchanged": PhotometricChange(),
        f"gain {third_pass.gain:g}, offset {third_pass.offset:+g}": PhotometricChange(
            gain=third_pass.gain, offset=third_pass.offset
        ),
        f"noise sigma {third_pass.noise_sigma:g}": PhotometricChange(
            noise_sigma=third_pass.noise_sigma, seed=NOISE_SEED
        ),
        f"blur sigma {third_pass.blur_sigma:g} px": PhotometricChange(blur_sigma=third_pass.blur_sigma),
        f"shift ({third_pass.shift_x:g}, {third_pass.shift_y:g}) px": PhotometricChange(
            shift_x=third_pass.shift_x, shift_y=third_pass.shift_y
        ),
        "darker: gain 0.6, offset -12": PhotometricChange(gain=0.6, offset=-12.0),
        "the third pass: gain, noise, blur and shift together": third_pass,
    }


def _counts(config: NeoSLAMConfig, change: PhotometricChange) -> tuple[int, int]:
    """Detections and placed objects over the 51 frames seen through a change."""
    sequence = read_kitti_sequence(data_root() / "kitti_06_51", "06")
    front_end = open_front_end(sequence, config.perception).front_end
    detections = placed = 0
    for index in range(len(sequence)):
        left, right = (change.apply(image, index, camera) for camera, image in enumerate(sequence.stereo_pair(index)))
        detected = front_end.detected(StereoPair(index, float(sequence.timestamps[index]), left, right))
        detections += len(detected.detections)
        placed += len(front_end.triangulated(detected).observations)
    return detections, placed


def photometric_rows(config: NeoSLAMConfig, third_pass: PhotometricChange) -> list[dict]:
    """A row per change: detections and placed objects with the configured contrast equalisation and without."""
    clip = config.perception.detector.contrast_clip
    detector = config.perception.detector.model_copy(update={"contrast_clip": 0.0})
    plain = config.model_copy(update={"perception": config.perception.model_copy(update={"detector": detector})})
    rows = []
    for name, change in changes(third_pass).items():
        equalised, as_seen = _counts(config, change), _counts(plain, change)
        rows.append(
            {
                "change": name,
                f"detections (CLAHE {clip:g})": equalised[0],
                f"placed (CLAHE {clip:g})": equalised[1],
                "detections (no CLAHE)": as_seen[0],
                "placed (no CLAHE)": as_seen[1],
            }
        )
    return rows
