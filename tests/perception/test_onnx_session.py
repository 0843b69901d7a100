"""Where the detector's network runs: onnxruntime's CPU provider by default, its CUDA provider when
`perception.detector.device` is cuda and the GPU build is installed, one line naming the extra when it is not."""

from __future__ import annotations

from pathlib import Path

import onnxruntime as ort
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.config.perception import DetectorConfig
from neoslam.errors import ConfigError
from neoslam.perception.onnx_session import GPU_EXTRA, execution_providers, open_session


def test_cpu_is_the_default_and_runs_on_the_cpu_provider_alone() -> None:
    assert NeoSLAMConfig().perception.detector.device == "cpu"
    assert execution_providers("cpu", ["CPUExecutionProvider"]) == ["CPUExecutionProvider"]
    assert execution_providers("cpu", ["CUDAExecutionProvider", "CPUExecutionProvider"]) == ["CPUExecutionProvider"]


def test_cuda_runs_on_the_cuda_provider_with_the_cpu_one_behind_it() -> None:
    available = ["TensorrtExecutionProvider", "CUDAExecutionProvider", "CPUExecutionProvider"]
    assert execution_providers("cuda", available) == ["CUDAExecutionProvider", "CPUExecutionProvider"]


def test_cuda_without_the_gpu_build_names_the_extra() -> None:
    with pytest.raises(ConfigError) as caught:
        execution_providers("cuda", ["CPUExecutionProvider"])
    message = str(caught.value)
    assert "perception.detector.device is 'cuda'" in message and "CUDAExecutionProvider" in message
    assert GPU_EXTRA in message and "device: cpu" in message


def test_an_unknown_device_is_refused_by_the_configuration() -> None:
    with pytest.raises(ValueError, match="device"):
        DetectorConfig(device="tpu")


@pytest.mark.skipif(
    "CUDAExecutionProvider" in ort.get_available_providers(), reason="a GPU build of onnxruntime is installed here"
)
def test_opening_a_model_on_cuda_here_is_refused_before_the_model_is_read(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="neoslam\\[gpu\\]"):
        open_session(tmp_path / "absent.onnx", 1, "see the docs", device="cuda")
