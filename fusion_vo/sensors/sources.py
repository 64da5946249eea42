"""What a sensor gives the consistency monitor (:mod:`fusion_vo.backends.monitor`): its heading components and the
distance it travels, each judged against the other sensors'. A :class:`~fusion_vo.sensors.registry.Sensor` lists
them in ``heading`` and ``distance``; the registry re-exports both classes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class HeadingSource:
    """A heading component of a sensor that the heading monitor judges against the others
    (:func:`fusion_vo.backends.monitor.check_heading_sources`; live: :mod:`fusion_vo.backends.live_monitor`).

    Attributes
    ----------
    key : str
        Its name in the check (``gyro``, ``ahrs``: one sensor may give several).
    component : str
        What its episodes call it (``"gyro yaw rate"``).
    rank : float
        Its place among the sources: the order they are judged and reported in; of the relative ones (not
        ``absolute``), the smaller carries the heading across a span where an absolute one was dropped.
    change : callable
        ``change(iv, config) -> (ok, angle, var) or None``: per node interval of the grid ``iv``, whether it has a
        heading change, the change [rad] and its variance [rad²] (None when it depends on the other sources:
        :attr:`variance`); None when the grid has none of its data. A ``biased`` source's change still holds its bias.
    variance : callable or None
        ``variance(iv, config, angle, found) -> var``: the variance of its changes given the others' (``found``:
        key -> ``(ok, angle)`` of every source as judged, a biased one's without its bias).
    window : callable or None
        ``window(iv, config) -> add``, ``add(span, theta) -> float``: the variance added to its change summed over a
        window of ``span`` seconds (an error shared over the window: an offset's walk, a scale; ``theta``: each
        source's summed change over the window).
    drop : callable
        ``drop(iv, bad, agrees)``: take the component out of ``iv`` (in place) in the intervals where ``bad``;
        ``agrees(a, b) -> bool``: whether its change over intervals ``[a, b)`` agrees with the others'.
    kept, clear : callable or None
        ``kept(iv) -> (K,) bool``: where it is still used after ``drop``; ``clear(iv)``: take it out of all of ``iv``.
        The live monitor decides for the sources that have them (None: the camera's increments, judged per
        increment in a whole recording only).
    suspect : bool
        Between two sources, this one is dropped when they disagree (the wheels' yaw: a twist's yaw rate from a
        nominal track width is the usual liar); two sources without a suspect judge nothing.
    absolute : bool
        An absolute heading (the AHRS), ``heading(iv) -> (ok, yaw)`` per node: after a span in which it disagreed it
        is trusted again only where its heading still agrees (``window`` over the gap is its offset's variance), it
        is dropped for a whole recording only when it disagrees throughout, and the live monitor never takes it
        back once dropped.
    heading : callable or None
        See ``absolute``.
    biased : bool
        Its change carries an unknown constant bias (a gyro's), estimated against the other sources and removed
        before it is judged: the median rate at rest where a source says the robot stands still (``at_rest``), else
        against the ``reference`` sources; while the live monitor cannot measure it, it neither judges nor is judged.
    reference : float or None
        Its rank as a reference for a biased source's bias (the smaller first; None: not one).
    reference_error : callable or None
        ``reference_error(iv, config, ok, var) -> float``: the error variance of its change summed where ``ok`` (the
        live monitor takes the reference with the smallest; one without is taken only when no other is there).
    at_rest : callable or None
        ``at_rest(iv, config) -> (K,) bool``: the intervals in which the robot stands still (the wheels').
    """

    key: str
    component: str
    rank: float
    change: Callable
    drop: Callable
    variance: Callable | None = None
    window: Callable | None = None
    kept: Callable | None = None
    clear: Callable | None = None
    suspect: bool = False
    absolute: bool = False
    heading: Callable | None = None
    biased: bool = False
    reference: float | None = None
    reference_error: Callable | None = None
    at_rest: Callable | None = None


@dataclass(frozen=True)
class DistanceSource:
    """The distance a sensor measures over each node interval, which the speed check compares with another's
    (:func:`fusion_vo.backends.monitor.check_speed_sources`; live: :mod:`fusion_vo.backends.live_monitor`).

    Attributes
    ----------
    key : str
        Its name in the check and in its episodes' ``against``.
    component : str
        What its episodes call the component dropped (``"speed"``).
    rank : float
        Its place among the sources (the smaller first).
    change : callable
        ``change(iv, config) -> (ok, distance, var) or None``: per node interval, whether it measures the distance
        travelled, the distance [m] and its variance [m²]; None when the grid ``iv`` has none of its data.
    drop : callable or None
        ``drop(iv, bad)``: take its distance out of ``iv`` (in place) where ``bad`` (per interval); the live monitor
        decides only for a suspect that has one.
    suspect : bool
        The one dropped when the two disagree (the wheels': slip and tyre changes are the common cause, and the
        other source keeps the translation); the check compares a suspect with the first other source.
    """

    key: str
    component: str
    rank: float
    change: Callable
    drop: Callable | None = None
    suspect: bool = False


__all__ = ["HeadingSource", "DistanceSource"]
