"""Training data from many sites: `wz dataset` on generated sites, cropped where the detector looks.

The detector looks at each camera's region of interest and far-field tile computed from the
road's geometry (:mod:`wz_camera_detector.regions`), so the model must know vehicles as every
mount sees them: from either shoulder or the median, 4-10 m up, through lenses of 50-100
degrees and four frame formats. For each site seed this renders ``--frames`` frames of a
generated site (:func:`wz_shared.site_generator.generate_site`; the weather cycles day, dusk,
rain, fog; 1200-2000 veh/h and 15-30 % trucks drawn from the seed), plus the default site's,
crops them to that site's own ROI and tile, shrinks each crop to the model's input side, and
writes one ultralytics dataset (``data.yaml`` listing every site's folder).

Run from the repository root, in the service's environment (no torch needed)::

    uv run python services/camera_detector/training/site_dataset.py --out /tmp/sites-ds \\
        --first-seed 200 --sites 48 --frames 25

Keep the evaluation's site seeds out of the training range.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

WEATHERS = ("day", "dusk", "rain", "fog")


def _render(job: tuple[Path, Path, int, str, float, float, int, float]) -> Path:
    site_file, out, seed, weather, vph, trucks, frames, every_s = job
    if not (out / "data.yaml").exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "wz_simulator.dataset",
                "--out",
                str(out),
                "--site",
                str(site_file),
                "--seed",
                str(seed),
                "--weather",
                weather,
                "--duration-s",
                str(frames * every_s),
                "--every-s",
                str(every_s),
                "--warmup-s",
                "60",
                "--val-share",
                "0.2",
                "--no-lidar",
                "--vehicles-per-hour",
                str(vph),
                "--truck-share",
                str(trucks),
            ],
            check=True,
            capture_output=True,
        )
    return out


def main(argv: list[str] | None = None) -> int:
    from wz_camera_detector.regions import detector_regions
    from wz_camera_detector.settings import camera_mount
    from wz_camera_detector.train_data import Roi, prepare_roi_dataset
    from wz_eval.site_tool import site_yaml
    from wz_shared.site import DEFAULT_SITE_PATH, load_site
    from wz_shared.site_generator import generate_site

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--first-seed", type=int, default=200)
    parser.add_argument("--sites", type=int, default=48)
    parser.add_argument("--frames", type=int, default=25, help="frames per site")
    parser.add_argument("--every-s", type=float, default=2.0)
    parser.add_argument("--default-seeds", type=int, nargs="*", default=[1, 11])
    parser.add_argument("--default-frames", type=int, default=50, help="per seed and weather")
    parser.add_argument("--input", type=int, default=480, help="the model's input side [px]")
    parser.add_argument("--quality", type=int, default=80, help="JPEG quality of the crops")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)

    raw, crops = args.out / "raw", args.out / "crops"
    (args.out / "sites").mkdir(parents=True, exist_ok=True)
    jobs = []
    for index in range(args.sites):
        seed = args.first_seed + index
        site = generate_site(seed)
        site_file = args.out / "sites" / f"gen-{seed}.yaml"
        site_file.write_text(site_yaml(site), encoding="utf-8")
        rng = np.random.default_rng(seed)
        vph = float(round(rng.uniform(1200, 2000) / 50) * 50)
        trucks = round(float(rng.uniform(0.15, 0.30)), 2)
        weather = WEATHERS[index % len(WEATHERS)]
        jobs.append(
            (site_file, raw / f"gen-{seed}", seed, weather, vph, trucks, args.frames, args.every_s)
        )
    for seed in args.default_seeds:
        for k, weather in enumerate(WEATHERS):
            jobs.append(
                (
                    DEFAULT_SITE_PATH,
                    raw / f"default-{seed}-{weather}",
                    seed + k,
                    weather,
                    1400.0,
                    0.15,
                    args.default_frames,
                    args.every_s,
                )
            )
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rendered = list(pool.map(_render, jobs))
    folders = []
    counts = {}
    for job, source in zip(jobs, rendered, strict=True):
        site = load_site(job[0])
        regions = detector_regions(site, camera_mount(site, None), args.input)
        if regions.roi_xyxy_px is None:
            continue
        dest = crops / source.name
        counts[source.name] = prepare_roi_dataset(
            [source],
            dest,
            Roi(*regions.roi_xyxy_px),
            tuple(Roi(*t) for t in regions.tiles_xyxy_px),
            max_side_px=args.input,
            jpeg_quality=args.quality,
        )
        folders.append(dest.relative_to(args.out))
    names = (rendered[0] / "data.yaml").read_text().split("names:", 1)[1]
    train = "\n".join(f"  - {f}/images/train" for f in folders)
    val = "\n".join(f"  - {f}/images/val" for f in folders)
    (args.out / "data.yaml").write_text(
        f"# {len(folders)} sites' crops (site_dataset.py)\npath: .\ntrain:\n{train}\nval:\n{val}\n"
        f"names:{names}"
    )
    (args.out / "manifest.json").write_text(
        json.dumps(
            {"args": vars(args) | {"out": str(args.out)}, "counts": counts}, indent=2, default=str
        )
    )
    total = sum(c["images_train"] + c["images_val"] for c in counts.values())
    sys.stdout.write(f"{len(folders)} sites, {total} images in {crops}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
