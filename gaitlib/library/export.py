"""The deployable form of a policy: the deterministic actor, observation normalizer included, as ONNX."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import torch

__all__ = ["export_onnx"]


def export_onnx(actor: torch.nn.Module, path: Path) -> None:
    """Export the deterministic actor (normalizer included) with rsl-rl's ONNX wrapper; the first axis of input
    ``obs`` (N, actor observation width) and output ``actions`` (N, 12) is the batch, of any size N."""
    model = actor.as_onnx(verbose=False).to("cpu").eval()
    buffer = io.BytesIO()  # made in memory, written by Python: a full disk is one OSError naming the file
    with warnings.catch_warnings():
        # The TorchScript exporter is chosen on purpose (an MLP needs nothing of torch.export, which pulls in
        # onnxscript); its deprecation notices say nothing about this export.
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        torch.onnx.export(
            model,
            model.get_dummy_inputs(),
            buffer,
            export_params=True,
            opset_version=18,
            input_names=model.input_names,
            output_names=model.output_names,
            dynamic_axes={name: {0: "batch"} for name in [*model.input_names, *model.output_names]},
            dynamo=False,
        )
    Path(path).write_bytes(buffer.getvalue())
