"""Number types of ``wz eval``'s command lines (argparse ``type=``): finite, positive, not
negative, a share from 0 to 1. Used by :mod:`wz_eval.cli` and :mod:`wz_eval.sites`."""

from __future__ import annotations

import argparse
import math


def number(text: str) -> float:
    """A finite number from the command line (``nan`` and ``inf`` refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def positive(text: str) -> float:
    """A finite number above 0."""
    if (value := number(text)) <= 0.0:
        raise argparse.ArgumentTypeError(f"{text} is not above 0")
    return value


def not_negative(text: str) -> float:
    """A finite number of at least 0."""
    if (value := number(text)) < 0.0:
        raise argparse.ArgumentTypeError(f"{text} is below 0")
    return value


def share(text: str) -> float:
    """A number from 0 to 1."""
    if not 0.0 <= (value := number(text)) <= 1.0:
        raise argparse.ArgumentTypeError(f"{text} is not a share from 0 to 1")
    return value


def demand_ratio(text: str) -> float:
    """Demand over capacity: above 0, at most 3 (three times capacity jams any closure)."""
    if not 0.0 < (value := number(text)) <= 3.0:
        raise argparse.ArgumentTypeError(f"{text} is not a demand ratio above 0 and at most 3")
    return value
