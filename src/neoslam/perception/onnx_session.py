"""Opening a detector's ONNX graph in onnxruntime, with an input whose height and width are free.

Exports such as YOLOX-Nano's declare a fixed 416x416 input although every layer works at any size that is a
multiple of the stride (its reshapes are [1, 85, -1], its upsampling is by scale). Declaring the two sides free,
without touching a weight, lets the same network look at a whole KITTI frame at its own resolution, where distant
cars are large enough to find; at 416x416 a 1226-px-wide frame shrinks threefold.
"""

from __future__ import annotations

from pathlib import Path

import onnx
import onnxruntime as ort

from neoslam.errors import ConfigError, InputError
from neoslam.inputs import MAX_MODEL_BYTES, check_input_file

__all__ = ["execution_providers", "free_input_size", "open_session"]

HEIGHT_AXIS, WIDTH_AXIS = 2, 3  # of an NCHW image input


def free_input_size(model: onnx.ModelProto) -> onnx.ModelProto:
    """The model with its first input's height and width, and every output's non-batch sides, made symbolic.

    Shapes recorded for intermediate values are dropped: they were inferred for the old size.
    """
    dims = model.graph.input[0].type.tensor_type.shape.dim
    for axis, name in ((HEIGHT_AXIS, "height"), (WIDTH_AXIS, "width")):
        dims[axis].ClearField("dim_value")
        dims[axis].dim_param = name
    for output in model.graph.output:
        for axis, dim in enumerate(output.type.tensor_type.shape.dim):
            if axis > 0:
                dim.ClearField("dim_value")
                dim.dim_param = f"{output.name}_{axis}"
    del model.graph.value_info[:]
    return model


PROVIDERS = {"cpu": "CPUExecutionProvider", "cuda": "CUDAExecutionProvider"}
# onnxruntime-gpu provides the same `onnxruntime` module as the CPU build: it replaces it, not joins it
GPU_EXTRA = 'pip uninstall onnxruntime && pip install "neoslam[gpu]"'


def execution_providers(device: str, available: list[str]) -> list[str]:
    """onnxruntime's providers for `device`, best first (the CPU provider last, for the operators a GPU provider
    leaves to it); ConfigError naming the extra when the device's provider is not among `available`."""
    wanted = PROVIDERS[device]
    if wanted not in available:
        raise ConfigError(
            f"perception.detector.device is {device!r}, but onnxruntime here has no {wanted} (it has "
            f"{', '.join(available) or 'none'}); install the GPU build with {GPU_EXTRA}, or set device: cpu"
        )
    return [wanted] if wanted == PROVIDERS["cpu"] else [wanted, PROVIDERS["cpu"]]


def open_session(
    path: Path, threads: int, help_text: str, entries: dict[str, str] | None = None, device: str = "cpu"
) -> ort.InferenceSession:
    """An onnxruntime session of the model at `path` with a free input size, on `device` (cpu or cuda); one line
    naming the file when the model is missing or cannot be loaded, or the extra when the device is not there."""
    providers = execution_providers(device, ort.get_available_providers())
    check_input_file(path, f"detector model not found: {help_text}", MAX_MODEL_BYTES)
    try:
        model = free_input_size(onnx.load(str(path)))
    except Exception as error:  # protobuf's decode errors derive from Exception only
        raise InputError(path, f"not an ONNX model ({error}); {help_text}") from error
    if len(model.graph.input[0].type.tensor_type.shape.dim) != WIDTH_AXIS + 1:
        raise InputError(path, f"the model's input is not an image (N, C, H, W); {help_text}")
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1  # one image at a time: nothing to run in parallel across operators
    options.log_severity_level = 3  # errors only; warnings would clutter the CLI's output
    # Spinning threads keep both cores busy after each inference and slow the OpenCV steps that follow (measured:
    # stereo odometry 46 ms per frame with spinning, 28 ms without).
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    for key, value in (entries or {}).items():
        options.add_session_config_entry(key, value)
    try:
        return ort.InferenceSession(model.SerializeToString(), options, providers=providers)
    except Exception as error:  # onnxruntime's load errors derive from Exception only (InvalidGraph, ...)
        raise InputError(path, f"cannot load the ONNX model ({error}); {help_text}") from error
