"""``wz eval``: the whole pipeline on the simulated work zone, scored against truth.

Usage::

    wz eval [--site FILE] [--duration-s 600] [--seed 7] [--max-range-m 150]
            [--drop SENSOR@START+SECONDS ...] [--bias-map FILE] [--write-bias-map FILE]
            [--mount-errors [--bump SENSOR@SECONDS[:DEG]]] [--json FILE] [--out DIR]
    wz eval --log LOG_DIR [--truth GPS_FILE] ...     (a field log: :mod:`wz_eval.field_run`)
    wz eval --sites N [--seed S] ...                 (generated sites: :mod:`wz_eval.sites`)
    wz eval --mast-check SURVEYED DISPLACED          (issue 39: :mod:`wz_eval.mast_check`)

The command line only (``python -m wz_eval.cli``, what ``wz eval`` runs): its options and which
evaluation they ask for. The simulated run and its scoring are :mod:`wz_eval.fusion`'s (its
docstring says what is scored and written).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from wz_eval.arguments import demand_ratio, not_negative, positive, share
from wz_eval.fusion import Dropout, EvalOptions, evaluate
from wz_eval.fusion_report import markdown
from wz_fusion_tracker.calibration import BiasMap, BiasMapError, load_bias_map, write_bias_map
from wz_shared.logs import configure_logging
from wz_shared.site import SiteFileError, load_site
from wz_simulator.sensors.mast import Bump
from wz_simulator.sensors.scene import WEATHER_PRESETS
from wz_simulator.settings import SimulatorSettings


def main(argv: list[str] | None = None) -> int:
    """``wz eval ARGS``: a field log's validation (``--log``, ``--truth``), generated sites
    (``--sites``) or the simulated run; its exit status (2: a usage error)."""
    arguments = sys.argv[1:] if argv is None else argv
    if any(a.split("=")[0] in ("--log", "--truth") for a in arguments):  # a field log
        from wz_eval.field_run import main as field_main

        return field_main(arguments)
    if any(a.split("=")[0] == "--mast-check" for a in arguments):  # two runs held together
        from wz_eval.mast_check import main as mast_check_main

        return mast_check_main(arguments)
    if any(a.split("=")[0] == "--sites" for a in arguments):  # generated sites
        from wz_eval.sites import main as sites_main

        return sites_main(arguments)
    parser = argparse.ArgumentParser(
        prog="wz eval",
        description=__doc__.split("\n")[0],
        epilog="With --log LOG_DIR [--truth GPS_FILE]: the paper's "
        "field validation on a field log instead (its own options). With --sites N [--seed S]: "
        "N generated sites, one report (its own options).",
    )
    parser.add_argument("--site", type=Path, default=SimulatorSettings().site_file)
    parser.add_argument("--duration-s", type=positive, default=600.0, help="scored [s]")
    parser.add_argument("--warmup-s", type=not_negative, default=60.0, help="before it [s]")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--max-range-m", type=positive, default=150.0)
    parser.add_argument("--weather", choices=sorted(WEATHER_PRESETS), default="day")
    parser.add_argument("--vehicles-per-hour", type=positive, default=1400.0)
    parser.add_argument(
        "--demand-ratio",
        type=demand_ratio,
        default=None,
        help="demand as a share of the closure's capacity (HCM work-zone lanes with the truck "
        "share; 0.5-0.85 flows freely, 1.05-1.3 queues); replaces --vehicles-per-hour, and "
        "drivers keep work-zone headways from the taper so that the closure carries that capacity",
    )
    parser.add_argument(
        "--demand-profile",
        choices=("steady", "ramp"),
        default="steady",
        help="ramp: free flow (0.6 of capacity) through the warm-up, up to the demand over the "
        "first tenth of the scored time, held half of it, down over a tenth: a queue forms and "
        "dissolves",
    )
    parser.add_argument("--truck-share", type=share, default=0.15, help="0 to 1")
    parser.add_argument("--aggressive-share", type=share, default=0.2, help="0 to 1")
    parser.add_argument(
        "--drop",
        action="append",
        default=[],
        metavar="SENSOR@START+SECONDS",
        help="silence a sensor (repeatable)",
    )
    parser.add_argument("--model", type=Path, default=None, help="camera model (.onnx)")
    parser.add_argument(
        "--bias-map",
        type=Path,
        default=None,
        metavar="FILE",
        help="remove each sensor's calibrated lateral bias (a map written by "
        "--write-bias-map from a run of another seed) before the tracker",
    )
    parser.add_argument(
        "--write-bias-map",
        type=Path,
        default=None,
        metavar="FILE",
        help="write the lateral bias map this run measured",
    )
    parser.add_argument(
        "--mount-errors",
        action="store_true",
        help="render the sensors as a real mast's (set-up errors, late clocks, sway, settling, "
        "drawn from --seed); the detectors and the tracker keep the site file's poses",
    )
    parser.add_argument(
        "--bump",
        default=None,
        metavar="SENSOR@SECONDS[:DEG]",
        help="with --mount-errors: knock SENSOR round its mast by DEG (default 2) SECONDS after "
        "the warm-up",
    )
    parser.add_argument(
        "--no-self-calibration",
        action="store_true",
        help="the detectors keep the site file's poses and the sensors' stamps (the sensors' "
        "self-calibration off; it is on by default, as in the services)",
    )
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=Path("runs/eval"))
    args = parser.parse_args(argv)
    try:
        dropouts = tuple(Dropout.parse(text) for text in args.drop)
    except ValueError as exc:
        parser.error(str(exc))
    try:
        site = load_site(args.site)
    except SiteFileError as exc:
        parser.error(str(exc))
    bump = None
    if args.bump is not None:
        if not args.mount_errors:
            parser.error("--bump needs --mount-errors (the bump is part of the mast model)")
        try:
            bump = Bump.parse(args.bump, after_s=args.warmup_s)
        except ValueError as exc:
            parser.error(str(exc))
        known = [mount.sensor_id for mount in site.sensors]
        if bump.sensor_id not in known:
            parser.error(
                f"--bump {args.bump!r}: site {site.site_id} has no sensor {bump.sensor_id!r} "
                f"(its sensors: {', '.join(known)})"
            )
    bias_map = None
    if args.bias_map is not None:
        try:
            bias_map = load_bias_map(args.bias_map, site)
        except BiasMapError as exc:
            parser.error(str(exc))
    configure_logging(service="eval", site=site.site_id, level="WARNING")
    options = EvalOptions(
        seed=args.seed,
        duration_s=args.duration_s,
        warmup_s=args.warmup_s,
        max_range_m=args.max_range_m,
        dropouts=dropouts,
        camera_model=args.model,
        vehicles_per_hour=args.vehicles_per_hour,
        demand_ratio=args.demand_ratio,
        demand_profile=args.demand_profile,
        weather=args.weather,
        truck_share=args.truck_share,
        aggressive_share=args.aggressive_share,
        bias_map=bias_map,
        mount_errors=args.mount_errors,
        bump=bump,
        self_calibration=not args.no_self_calibration,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    report = evaluate(site, options, plots_dir=args.out)
    if args.write_bias_map is not None:
        write_bias_map(args.write_bias_map, BiasMap.model_validate(report["measured_bias_map"]))
    text = json.dumps(report, indent=2, default=str)
    (args.json or args.out / "eval.json").write_text(text + "\n")
    summary = markdown(report)
    (args.out / "eval.md").write_text(summary)
    sys.stdout.write(summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
