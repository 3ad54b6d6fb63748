"""Adds the Piper voice's phoneme durations as a second graph output (`make model-voice`, scripts/model.sh).

A Piper (VITS) voice computes, for every phoneme id, how many spectrogram frames it lasts: one Ceil node
(`/Ceil` -> `/Ceil_output_0`, shape [1, 1, ids], frames of 256 samples), read by the ReduceSum that sizes the
audio and the CumSum that spreads the ids over it. The published graph outputs only the audio; this script marks
that tensor as an output too, so that the agent's Piper engine reads each phoneme's length on the PCM's own
sample clock. Nothing else in the graph changes. Usage: add_durations.py IN.onnx OUT.onnx
"""

import sys

import onnx
from onnx import TensorProto, helper

DURATIONS = "/Ceil_output_0"


def main(source: str, target: str) -> None:
    model = onnx.load(source)
    producers = [node for node in model.graph.node if DURATIONS in node.output]
    if len(producers) != 1 or producers[0].op_type != "Ceil":
        sys.exit(f"{source}: expected exactly one Ceil node producing {DURATIONS}, found {len(producers)}")
    if any(output.name == DURATIONS for output in model.graph.output):
        sys.exit(f"{source}: {DURATIONS} is already an output")
    model.graph.output.append(helper.make_tensor_value_info(DURATIONS, TensorProto.FLOAT, ["batch_size", 1, "phonemes"]))
    onnx.checker.check_model(model)
    onnx.save(model, target)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: add_durations.py IN.onnx OUT.onnx")
    main(sys.argv[1], sys.argv[2])
