"""TensorFlow frozen graphs (``GraphDef``), written and read without TensorFlow.

The physical car loads a frozen graph (``model.pb``); a DeepRacer model brings one. TensorFlow is
a gigabyte that neither the web tier nor the workers need for this: a frozen graph is a protobuf
``GraphDef`` whose weights are ``Const`` nodes. The messages below are TensorFlow's own
(tensorflow/core/framework/graph.proto, node_def.proto, attr_value.proto, tensor.proto,
tensor_shape.proto, types.proto, versions.proto; and tensor_bundle.proto's checkpoint index
entries, which ``rl.tfcheckpoint`` reads), declared with the fields a frozen inference
graph uses and under TensorFlow's field numbers, so that protobuf's runtime encodes and decodes
them byte for byte as TensorFlow does. The tests load what this writes with TensorFlow itself and
with OpenVINO's TensorFlow front end, as the car's model optimizer does.
"""

from __future__ import annotations

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

# types.proto
DT_FLOAT, DT_INT32 = 1, 3
_DTYPES = {DT_FLOAT: np.dtype("<f4"), DT_INT32: np.dtype("<i4")}
# versions.proto: the GraphDef version of the writer. TensorFlow reads any producer from
# TF_GRAPH_DEF_VERSION_MIN_PRODUCER (0) on (core/public/version.h); 27 is TensorFlow 1.x's era, in
# which DeepRacer's graphs were written, and none of the ops used here changed since.
PRODUCER = 27

_F = descriptor_pb2.FieldDescriptorProto
_SCALARS = {
    "string": _F.TYPE_STRING,
    "bytes": _F.TYPE_BYTES,
    "int32": _F.TYPE_INT32,
    "int64": _F.TYPE_INT64,
    "float": _F.TYPE_FLOAT,
    "bool": _F.TYPE_BOOL,
    "fixed32": _F.TYPE_FIXED32,
}


def _message(file, name: str, fields, *, oneof: str | None = None, parent=None):
    """Declare message ``name`` with ``fields``: (name, number, type, repeated); a type not in
    ``_SCALARS`` is a message type's full name."""
    message = (parent.nested_type if parent is not None else file.message_type).add(name=name)
    if oneof:
        message.oneof_decl.add(name=oneof)
    for field_name, number, kind, repeated in fields:
        field = message.field.add(name=field_name, number=number)
        field.label = _F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
        if kind in _SCALARS:
            field.type = _SCALARS[kind]
        else:
            field.type, field.type_name = _F.TYPE_MESSAGE, kind
        if oneof and not repeated:
            field.oneof_index = 0  # TensorFlow's AttrValue is a oneof: zero values are kept
    return message


# Long because it declares TensorFlow's graph messages field by field, one table each.
def _declare():
    file = descriptor_pb2.FileDescriptorProto(
        name="pitlane/tensorflow_graph.proto", package="tensorflow", syntax="proto3"
    )
    shape = _message(
        file,
        "TensorShapeProto",
        [
            ("dim", 2, ".tensorflow.TensorShapeProto.Dim", True),
            ("unknown_rank", 3, "bool", False),
        ],
    )
    _message(file, "Dim", [("size", 1, "int64", False), ("name", 2, "string", False)], parent=shape)
    _message(file, "TensorProto", [
        ("dtype", 1, "int32", False), ("tensor_shape", 2, ".tensorflow.TensorShapeProto", False),
        ("version_number", 3, "int32", False), ("tensor_content", 4, "bytes", False),
        ("float_val", 5, "float", True), ("int_val", 7, "int32", True),
    ])  # fmt: skip
    attr = _message(file, "AttrValue", [
        ("list", 1, ".tensorflow.AttrValue.ListValue", False), ("s", 2, "bytes", False),
        ("i", 3, "int64", False), ("f", 4, "float", False), ("b", 5, "bool", False),
        ("type", 6, "int32", False), ("shape", 7, ".tensorflow.TensorShapeProto", False),
        ("tensor", 8, ".tensorflow.TensorProto", False),
    ], oneof="value")  # fmt: skip
    _message(file, "ListValue", [
        ("s", 2, "bytes", True), ("i", 3, "int64", True), ("f", 4, "float", True),
        ("b", 5, "bool", True), ("type", 6, "int32", True),
        ("shape", 7, ".tensorflow.TensorShapeProto", True),
    ], parent=attr)  # fmt: skip
    node = _message(file, "NodeDef", [
        ("name", 1, "string", False), ("op", 2, "string", False), ("input", 3, "string", True),
        ("device", 4, "string", False), ("attr", 5, ".tensorflow.NodeDef.AttrEntry", True),
    ])  # fmt: skip
    entry = _message(
        file,
        "AttrEntry",
        [
            ("key", 1, "string", False),
            ("value", 2, ".tensorflow.AttrValue", False),
        ],
        parent=node,
    )
    entry.options.map_entry = True
    _message(file, "VersionDef", [
        ("producer", 1, "int32", False), ("min_consumer", 2, "int32", False),
        ("bad_consumers", 3, "int32", True),
    ])  # fmt: skip
    _message(
        file,
        "GraphDef",
        [
            ("node", 1, ".tensorflow.NodeDef", True),
            ("versions", 4, ".tensorflow.VersionDef", False),
        ],
    )
    # tensor_bundle.proto: a checkpoint's index entries (read and written by rl.tfcheckpoint)
    _message(file, "BundleEntryProto", [
        ("dtype", 1, "int32", False), ("shape", 2, ".tensorflow.TensorShapeProto", False),
        ("shard_id", 3, "int32", False), ("offset", 4, "int64", False),
        ("size", 5, "int64", False), ("crc32c", 6, "fixed32", False), ("slices", 7, "bytes", True),
    ])  # fmt: skip
    _message(
        file,
        "BundleHeaderProto",
        [
            ("num_shards", 1, "int32", False),
            ("endianness", 2, "int32", False),
            ("version", 3, ".tensorflow.VersionDef", False),
        ],
    )
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file)
    return [
        message_factory.GetMessageClass(pool.FindMessageTypeByName(f"tensorflow.{name}"))
        for name in ("GraphDef", "TensorProto", "BundleEntryProto", "BundleHeaderProto")
    ]


GraphDef, TensorProto, BundleEntryProto, BundleHeaderProto = _declare()


class Graph:
    """A frozen inference graph under construction: ``add`` nodes, then ``serialize``. Each
    method returns the name of the node it added, the input of the next."""

    def __init__(self) -> None:
        self.graph = GraphDef()
        self.graph.versions.producer = PRODUCER

    def serialize(self) -> bytes:
        return self.graph.SerializeToString(deterministic=True)

    def add(self, name: str, op: str, inputs=(), **attrs) -> str:
        node = self.graph.node.add(name=name, op=op)
        node.input.extend(inputs)
        for key, value in attrs.items():
            _set_attr(node.attr[key], value)
        return name

    def placeholder(self, name: str, shape: list[int]) -> str:
        return self.add(name, "Placeholder", dtype=_Type(DT_FLOAT), shape=_Shape(shape))

    def const(self, name: str, value) -> str:
        array = np.asarray(value)
        dtype = DT_INT32 if array.dtype.kind in "iu" else DT_FLOAT
        return self.add(name, "Const", dtype=_Type(dtype), value=_tensor(array, dtype))

    def conv2d(self, scope: str, x: str, kernel: np.ndarray, bias: np.ndarray, stride: int) -> str:
        """A convolution as TensorFlow's Conv2D: NHWC, unpadded, ``kernel`` as HWIO."""
        conv = self.add(
            f"{scope}/Conv2D",
            "Conv2D",
            [x, self.const(f"{scope}/kernel", kernel)],
            T=_Type(DT_FLOAT),
            strides=[1, stride, stride, 1],
            padding=b"VALID",
            data_format=b"NHWC",
            dilations=[1, 1, 1, 1],
            use_cudnn_on_gpu=True,
            explicit_paddings=[],
        )
        return self.bias_add(scope, conv, bias)

    def dense(self, scope: str, x: str, kernel: np.ndarray, bias: np.ndarray) -> str:
        """x @ kernel + bias, ``kernel`` as TensorFlow keeps it: [in, out]."""
        product = self.add(
            f"{scope}/MatMul",
            "MatMul",
            [x, self.const(f"{scope}/kernel", kernel)],
            T=_Type(DT_FLOAT),
            transpose_a=False,
            transpose_b=False,
        )
        return self.bias_add(scope, product, bias)

    def bias_add(self, scope: str, x: str, bias: np.ndarray) -> str:
        return self.add(
            f"{scope}/BiasAdd",
            "BiasAdd",
            [x, self.const(f"{scope}/bias", bias)],
            T=_Type(DT_FLOAT),
            data_format=b"NHWC",
        )

    def unary(self, name: str, op: str, x: str) -> str:
        """Relu, Tanh, Softmax, Identity."""
        return self.add(name, op, [x], T=_Type(DT_FLOAT))

    def divide(self, name: str, x: str, by: float) -> str:
        return self.add(
            name, "RealDiv", [x, self.const(f"{name}/y", np.float32(by))], T=_Type(DT_FLOAT)
        )

    def reshape(self, name: str, x: str, shape: list[int]) -> str:
        return self.add(
            name,
            "Reshape",
            [x, self.const(f"{name}/shape", np.array(shape, np.int32))],
            T=_Type(DT_FLOAT),
            Tshape=_Type(DT_INT32),
        )

    def concat(self, name: str, xs: list[str], axis: int) -> str:
        return self.add(
            name,
            "ConcatV2",
            [*xs, self.const(f"{name}/axis", np.int32(axis))],
            N=len(xs),
            T=_Type(DT_FLOAT),
            Tidx=_Type(DT_INT32),
        )


class _Type(int):
    """An attribute that is a DataType, not an integer."""


class _Shape(list):
    """An attribute that is a TensorShapeProto, not a list of integers."""


def _set_attr(attr, value) -> None:
    if isinstance(value, _Type):
        attr.type = int(value)
    elif isinstance(value, _Shape):
        _set_shape(attr.shape, value)
    elif isinstance(value, bool):
        attr.b = value
    elif isinstance(value, int):
        attr.i = value
    elif isinstance(value, bytes):
        attr.s = value
    elif isinstance(value, list):
        attr.list.i.extend(value)  # an empty list is still a list: the field is set
        attr.list.SetInParent()
    else:
        attr.tensor.CopyFrom(value)


def _set_shape(proto, shape) -> None:
    for size in shape:
        proto.dim.add(size=size)


def _tensor(array: np.ndarray, dtype: int):
    """A scalar's value goes in float_val or int_val, as TensorFlow writes one (OpenVINO's
    front end reads a scalar from there only); an array's, packed in tensor_content."""
    proto = TensorProto(dtype=dtype)
    _set_shape(proto.tensor_shape, array.shape)
    if array.ndim == 0:
        (proto.int_val if dtype == DT_INT32 else proto.float_val).append(array.item())
    else:
        proto.tensor_content = np.ascontiguousarray(array, dtype=_DTYPES[dtype]).tobytes()
    return proto


def constants(data: bytes) -> dict[str, np.ndarray]:
    """The float32 ``Const`` nodes of a serialized frozen graph, by node name: its weights.

    TensorFlow writes a tensor's values either packed in ``tensor_content`` or, for small or
    uniform ones, in ``float_val`` (one value meaning "all of them")."""
    graph = GraphDef.FromString(data)
    found = {}
    for node in graph.node:
        if node.op != "Const" or "value" not in node.attr:
            continue
        tensor = node.attr["value"].tensor
        if tensor.dtype != DT_FLOAT:
            continue
        shape = tuple(dim.size for dim in tensor.tensor_shape.dim)
        count = int(np.prod(shape, dtype=np.int64))
        if tensor.tensor_content:
            values = np.frombuffer(tensor.tensor_content, dtype=_DTYPES[DT_FLOAT])
        else:
            values = np.asarray(tensor.float_val, dtype=np.float32)
            if len(values) == 1:
                values = np.full(count, values[0], np.float32)
        if values.size != count:
            raise ValueError(f"{node.name}: {values.size} values for a tensor of shape {shape}")
        found[node.name] = values.reshape(shape).copy()
    return found
