"""The inputs and outputs of an ONNX model, read from its protobuf bytes without the ``onnx`` package.

Every library entry's ``deployment`` block is checked against its ``policy.onnx`` each time the entry loads
(:func:`gaitlib.library.validate.check_deployment`). Importing ``onnx`` for that took about 0.7 s of each command's
start (with its ``ml_dtypes`` extension; ``docs/benchmarks.md``, "A command's start"), for four facts a graph's
signature holds: each input's and output's name, element type and shape. This module decodes just those fields of the
ONNX protobuf schema (``onnx/onnx.proto``, github.com/onnx/onnx): ``ModelProto.graph`` (7), ``GraphProto.input`` (11)
and ``output`` (12), ``ValueInfoProto.name`` (1) and ``type`` (2), ``TypeProto.tensor_type`` (1),
``TypeProto.Tensor.elem_type`` (1) and ``shape`` (2), ``TensorShapeProto.dim`` (1), ``Dimension.dim_value`` (1) and
``dim_param`` (2). Other fields are skipped by their wire type; a repeated singular field merges as protobuf merges it
(messages concatenated, the last scalar wins). Malformed bytes raise :class:`ValueError`.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["graph_signature"]

_DTYPES = {
    1: "float32", 2: "uint8", 3: "int8", 4: "uint16", 5: "int16", 6: "int32", 7: "int64", 8: "object", 9: "bool",
    10: "float16", 11: "float64", 12: "uint32", 13: "uint64", 14: "complex64", 15: "complex128",
}
"""``TensorProto.DataType`` to numpy's dtype name, as ``onnx.helper.tensor_dtype_to_np_dtype`` maps them."""


def graph_signature(path: Path) -> dict[str, list[dict]]:
    """``{"inputs": [...], "outputs": [...]}`` of the ONNX model at ``path``: each a ``{"name", "shape", "dtype"}``
    dict, a shape's dimension its value or, where it has none, its symbolic name ("" where neither is set)."""
    graph = _merged(_fields(path.read_bytes()), 7)
    fields = _fields(graph)
    return {"inputs": [_value_info(b) for n, b in fields if n == 11],
            "outputs": [_value_info(b) for n, b in fields if n == 12]}


def _value_info(data: bytes) -> dict:
    fields = _fields(data)
    tensor = _fields(_merged(_fields(_merged(fields, 2)), 1))
    dims = [_fields(b) for n, b in _fields(_merged(tensor, 2)) if n == 1]
    elem_type = _last(tensor, 1, 0)
    if elem_type not in _DTYPES:
        raise ValueError(f"an ONNX tensor of element type {elem_type}")
    return {
        "name": _last(fields, 1, b"").decode(),
        "shape": [_last(d, 1, 0) or _last(d, 2, b"").decode() for d in dims],
        "dtype": _DTYPES[elem_type],
    }


def _merged(fields: list[tuple[int, int | bytes]], number: int) -> bytes:
    """A singular message field's bytes: every occurrence concatenated, which protobuf parses as their merge."""
    return b"".join(value for n, value in fields if n == number and isinstance(value, bytes))


def _last(fields: list[tuple[int, int | bytes]], number: int, default: int | bytes) -> int | bytes:
    """A singular scalar or string field: its last occurrence of ``default``'s kind, else ``default``."""
    values = [value for n, value in fields if n == number and type(value) is type(default)]
    return values[-1] if values else default


def _fields(data: bytes) -> list[tuple[int, int | bytes]]:
    """One protobuf message's fields in order: (number, varint) or (number, length-delimited bytes); fixed-width
    fields are skipped."""
    fields, at = [], 0
    while at < len(data):
        key, at = _varint(data, at)
        number, wire = key >> 3, key & 7
        if number == 0:
            raise ValueError("a protobuf field numbered 0")
        if wire == 0:
            value, at = _varint(data, at)
            fields.append((number, value - (1 << 64) if value >> 63 else value))  # int32 and int64 are signed
        elif wire == 2:
            size, at = _varint(data, at)
            if at + size > len(data):
                raise ValueError("a protobuf field longer than its message")
            fields.append((number, data[at:at + size]))
            at += size
        elif wire in (1, 5):
            at += 8 if wire == 1 else 4
            if at > len(data):
                raise ValueError("a protobuf field longer than its message")
        else:
            raise ValueError(f"a protobuf wire type {wire} this reader does not take")
    return fields


def _varint(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if at >= len(data) or shift > 63:
            raise ValueError("a truncated or overlong protobuf varint")
        byte = data[at]
        value |= (byte & 0x7F) << shift
        at, shift = at + 1, shift + 7
        if byte < 0x80:
            return value & 0xFFFFFFFFFFFFFFFF, at  # unsigned: a length or key never comes out negative
