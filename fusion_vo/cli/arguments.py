"""``argparse`` types shared by the commands (a bad value is a usage error naming the option, exit 2)."""

from __future__ import annotations

import argparse
import math
from typing import Callable


def whole_number(minimum: int, reason: str = "", maximum: int | None = None) -> Callable[[str], int]:
    """An ``argparse`` type: a whole number of at least ``minimum`` and, when given, at most ``maximum``
    (``reason`` says why, in the error)."""
    why = f" ({reason})" if reason else ""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, not '{text}'") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}{why}, not {value}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum}{why}, not {value}")
        return value

    parse.__name__ = f"whole number >= {minimum}" + (f" and <= {maximum}" if maximum is not None else "")
    return parse


#: a random seed (numpy's generators take whole numbers of at least 0)
random_seed = whole_number(0, "a random seed")
#: a whole number of at least 1 (threads, repeats)
positive_int = whole_number(1)
#: a number of frames: at least one frame pair
frame_count = whole_number(2, "one frame pair")
#: most threads a run may use (``odometry.threads`` of ``fusion_vo.config.odometry.OdometryConfig``, not imported here
#: so that ``--help`` stays fast; ``tests/faults/test_command_faults.py`` checks that the two agree)
MAX_THREADS = 256
#: a number of threads (``--threads``)
thread_count = whole_number(1, maximum=MAX_THREADS)
#: a number of worker processes (``--workers``): one per core of a large machine at most
worker_count = whole_number(1, "worker processes", maximum=MAX_THREADS)
#: a number of interleaved repeats of a measurement (``bench --repeats``)
repeat_count = whole_number(1, maximum=100)


def non_empty(option: str) -> Callable[[str], str]:
    """An ``argparse`` type: a text that is not empty or blank (a file, folder or topic name): an empty value
    would otherwise silently mean the current folder or the default."""

    def parse(text: str) -> str:
        if not text.strip():
            raise argparse.ArgumentTypeError(f"expected {option}, not {text!r}")
        return text

    parse.__name__ = option
    return parse


def frame_id(text: str) -> str:
    """An ``argparse`` type: a ROS frame name (not empty, no spaces)."""
    if not text.strip() or any(c.isspace() for c in text):
        raise argparse.ArgumentTypeError(f"expected a frame name such as 'odom' (no spaces), not {text!r}")
    return text


def finite_number(text: str) -> float:
    """An ``argparse`` type: a finite number (not NaN or infinite)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: '{text}'") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, not {text}")
    return value


def non_negative_number(text: str) -> float:
    """An ``argparse`` type: a finite number >= 0 (a standard deviation, a delay, a speed)."""
    value = finite_number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, not {text}")
    return value


def positive_number(text: str) -> float:
    """An ``argparse`` type: a finite number > 0 (a length, a rate, a focal length)."""
    value = non_negative_number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, not {text}")
    return value


def number_up_to(maximum: float, reason: str) -> Callable[[str], float]:
    """An ``argparse`` type: a finite number > 0 and at most ``maximum`` (``reason`` says why, in the error)."""

    def parse(text: str) -> float:
        value = positive_number(text)
        if value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum:g} ({reason}), not {text}")
        return value

    parse.__name__ = f"number in (0, {maximum:g}]"
    return parse


#: slowest and fastest playback speeds other than 0 (as fast as possible): a hundredth of the recording's pace
#: (12 s of recording then take 20 minutes) to a million times it
MIN_SPEED, MAX_SPEED = 0.01, 1e6


def playback_speed(text: str) -> float:
    """An ``argparse`` type: 0 (as fast as possible) or a speed from :data:`MIN_SPEED` to :data:`MAX_SPEED`."""
    value = non_negative_number(text)
    if value != 0 and not MIN_SPEED <= value <= MAX_SPEED:
        raise argparse.ArgumentTypeError(f"must be 0 (as fast as possible) or from {MIN_SPEED:g} to {MAX_SPEED:g} "
                                         f"times the recording's pace, not {text}")
    return value
