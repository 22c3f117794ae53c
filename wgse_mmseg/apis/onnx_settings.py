"""The settings of an ONNX export (:mod:`.onnx_export`): the opsets it
offers, the input sizes a command line accepts and the agreement with the
torch model it requires. Kept apart from the export, which needs torch,
ONNX and MMSeg, so that the tools' command lines read them at once."""
from ..command_line import Integer
from ..limits import MAX_NUM_STEPS

__all__ = []

#: the largest ``|logits_onnx - logits_torch|`` accepted, relative to
#: ``max(1, max |logits_torch|)``: float32 rounding through a different
#: order of operations (measured: below 1e-5 for every shipped config)
LOGITS_TOLERANCE = 1e-4
#: the least share of pixels whose class (argmax over the logits) the ONNX
#: graph must give as the torch model does
MIN_ARGMAX_AGREEMENT = 0.999
#: the ONNX opsets the export offers (the dynamo exporter's range that
#: ONNX Runtime 1.32 runs), as a command line reads one; :data:`OPSET` is
#: the default
OPSETS = Integer(18, 23)
OPSET = 18
#: each of ``T``, ``H`` and ``W`` of an export, on a command line (a side
#: above :data:`~wgse_mmseg.limits.MAX_NUM_STEPS` would not fit a
#: runtime's memory anyway)
SHAPE_ENTRY = Integer(1, MAX_NUM_STEPS)
