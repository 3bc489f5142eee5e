"""Train the camera model with ultralytics on `wz dataset` folders and export it to ONNX.

Run it in the training environment (``./setup.sh`` creates ``.train/``), from the repository root::

    PYTHONPATH=services/camera_detector/src .train/bin/python \
        services/camera_detector/training/train.py --data DS1 DS2 --heldout DS3 --out DIR

Steps: crop every frame to the camera's region of interest (``wz_camera_detector.train_data``);
train ``wz-yolov8-pico.yaml`` from scratch (no pretrained weights can be downloaded here); export
the best epoch to ONNX at a fixed input size; write into the ONNX file's metadata the ROI and the
class names the service needs (it reads them at start-up); write ``training.json`` (recipe,
data manifests, ultralytics' own validation figures). ultralytics is kept offline: YOLO_OFFLINE=1,
YOLO_AUTOINSTALL=false, and a local font copied into its config folder so plotting does not try
to download Arial.ttf.

The validation figures that the issue asks for (mAP50 and recall of vehicles within 100 m and at
least 50 % visible) come from ``python -m wz_camera_detector.validate`` on the held-out set with
our own ONNX Runtime pipeline, not from ultralytics.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _offline(config_dir: Path) -> None:
    """Keep ultralytics from reaching out (call before importing it)."""
    config_dir.mkdir(parents=True, exist_ok=True)
    os.environ["YOLO_OFFLINE"] = "1"
    os.environ["YOLO_AUTOINSTALL"] = "false"
    os.environ["YOLO_CONFIG_DIR"] = str(config_dir)
    font = config_dir / "Arial.ttf"
    if not font.exists():
        import matplotlib

        dejavu = Path(matplotlib.__file__).parent / "mpl-data" / "fonts" / "ttf" / "DejaVuSans.ttf"
        shutil.copyfile(dejavu, font)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--data",
        type=Path,
        nargs="+",
        default=[],
        help="wz dataset folders (train and val splits), cropped here to --roi",
    )
    parser.add_argument(
        "--prepared",
        type=Path,
        default=None,
        help="an already cropped dataset's data.yaml (site_dataset.py: every site cropped to "
        "its own ROI and tile); the model's metadata then carries no ROI: the service computes "
        "each camera's from the road's geometry",
    )
    parser.add_argument("--device", default="cpu", help="cpu, or a CUDA device such as 0")
    parser.add_argument("--no-plots", action="store_true", help="no ultralytics plots")
    parser.add_argument("--no-simplify", action="store_true", help="export without onnxslim")
    parser.add_argument("--out", type=Path, required=True, help="work folder")
    parser.add_argument("--roi", default="480,440,1200,1160", help="x0,y0,x1,y1 [px]")
    parser.add_argument("--imgsz", type=int, default=480)
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", type=Path, default=HERE / "wz-yolov8-pico.yaml")
    parser.add_argument("--name", default="wz-vehicles-pico")
    parser.add_argument(
        "--time-h",
        type=float,
        default=None,
        help="stop training after this many hours (ultralytics' time=)",
    )
    parser.add_argument(
        "--weights",
        type=Path,
        default=None,
        help="start from these weights (.pt of an earlier run): a fine-tune",
    )
    parser.add_argument("--lr0", type=float, default=None, help="initial learning rate")
    parser.add_argument(
        "--train-tiles",
        action="store_true",
        help="also train on the far-field tile crops of every frame",
    )
    parser.add_argument(
        "--close-mosaic",
        type=int,
        default=None,
        help="epochs at the end without mosaic (default: a fifth)",
    )
    parser.add_argument(
        "--tiles",
        default="540,440,780,560",
        help="far-field tiles x0,y0,x1,y1;... written to the model's metadata ('' for none)",
    )
    args = parser.parse_args(argv)
    if not args.data and args.prepared is None:
        parser.error("give --data folders or a --prepared data.yaml")

    from wz_camera_detector.train_data import Roi, prepare_roi_dataset

    roi = Roi.parse(args.roi)
    args.out.mkdir(parents=True, exist_ok=True)
    _offline(args.out / "yolo-config")
    if args.prepared is not None:
        data_yaml = args.prepared.resolve()
        manifest_path = data_yaml.parent / "manifest.json"
    else:
        roi_data = args.out / "roi-dataset"
        if roi_data.exists():
            shutil.rmtree(roi_data)
        tiles = tuple(Roi.parse(t) for t in args.tiles.split(";") if t.strip())
        counts = prepare_roi_dataset(
            list(args.data), roi_data, roi, tiles if args.train_tiles else ()
        )
        sys.stdout.write(f"ROI dataset {roi.as_tuple()}: {counts}\n")
        data_yaml = roi_data / "data.yaml"
        manifest_path = roi_data / "manifest.json"

    from ultralytics import YOLO

    started = time.time()
    model = YOLO(str(args.weights if args.weights is not None else args.model))
    train_args = {
        "data": str(data_yaml),
        "epochs": args.epochs,
        "imgsz": args.imgsz,
        "batch": args.batch,
        "workers": args.workers,
        "device": args.device,
        "seed": args.seed,
        "deterministic": True,
        "pretrained": False,
        "amp": False,
        "cache": "ram",
        "project": str(args.out / "runs"),
        "name": args.name,
        "exist_ok": True,
        "close_mosaic": (
            args.close_mosaic if args.close_mosaic is not None else max(1, args.epochs // 5)
        ),
        "patience": args.epochs,
        "plots": not args.no_plots,
    }
    if args.weights is not None:
        train_args["pretrained"] = True
        train_args["warmup_epochs"] = 1
    if args.lr0 is not None:
        train_args["lr0"] = args.lr0
        train_args["optimizer"] = "AdamW"  # 'auto' would pick its own rate
    if args.time_h is not None:
        train_args["time"] = args.time_h
    model.train(**train_args)
    train_s = time.time() - started
    run_dir = args.out / "runs" / args.name
    best = run_dir / "weights" / "best.pt"
    trained = YOLO(str(best))
    metrics = trained.val(
        data=str(data_yaml),
        imgsz=args.imgsz,
        batch=args.batch,
        device=args.device,
        plots=False,
        project=str(args.out / "runs"),
        name=f"{args.name}-val",
        exist_ok=True,
    )
    exported = Path(
        trained.export(
            format="onnx",
            imgsz=args.imgsz,
            opset=17,
            simplify=not args.no_simplify,
            dynamic=False,
            device="cpu",
        )
    )

    import onnx

    names = [trained.names[i] for i in sorted(trained.names)]
    proto = onnx.load(str(exported))
    extra = {
        "wz_roi_xyxy_px": ",".join(str(v) for v in roi.as_tuple()),
        "wz_class_names": ",".join(names),
        "wz_input_size": f"{args.imgsz},{args.imgsz}",
        "wz_tiles_xyxy_px": args.tiles,
        "wz_recipe": "services/camera_detector/training/README.md",
    }
    if not args.tiles:
        del extra["wz_tiles_xyxy_px"]
    if args.prepared is not None:  # many cameras: each one's regions come from its geometry
        del extra["wz_roi_xyxy_px"]
        extra.pop("wz_tiles_xyxy_px", None)
        extra["wz_regions"] = "geometry"
    kept = [p for p in proto.metadata_props if p.key not in extra]
    del proto.metadata_props[:]
    proto.metadata_props.extend(kept)
    for key, value in extra.items():
        proto.metadata_props.add(key=key, value=value)
    final = args.out / f"{args.name}-{args.imgsz}.onnx"
    onnx.save(proto, str(final))
    box = metrics.box
    record = {
        "model": final.name,
        "architecture": args.model.name,
        "started_from": str(args.weights) if args.weights is not None else "scratch",
        "tiles_xyxy_px": args.tiles if args.prepared is None else "geometry",
        "input_size_px": [args.imgsz, args.imgsz],
        "roi_xyxy_px": list(roi.as_tuple()) if args.prepared is None else "geometry",
        "class_names": names,
        "train_args": train_args | {"data": data_yaml.name, "project": "runs"},
        "train_seconds": round(train_s, 1),
        "ultralytics_val_all_labels": {
            "precision": float(box.mp),
            "recall": float(box.mr),
            "map50": float(box.map50),
            "map50_95": float(box.map),
        },
        "datasets": json.loads(manifest_path.read_text()) if manifest_path.exists() else None,
    }
    (args.out / "training.json").write_text(json.dumps(record, indent=2))
    sys.stdout.write(f"model {final}\n{json.dumps(record['ultralytics_val_all_labels'])}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
