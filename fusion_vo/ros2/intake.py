"""The node's worker threads: samples to the fusion in time order, and the outputs the timers ask for.

A callback only converts its message and :meth:`Intake.put` s the sample (a few tens of microseconds), so
the executor drains every topic's queue promptly; the fusion's work (about half a millisecond a sample)
happens on the intake's own thread. Each time it wakes it takes everything waiting and hands it to the
fusion sorted by stamp, so when the process falls behind (a busy machine) every input falls behind
together instead of the highest-rate one lagging the others by more than the fusion's history (the
executor takes one message per ready topic per turn). At most ``capacity`` samples wait; beyond that the
oldest is dropped and counted (``overflow``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque

log = logging.getLogger(__name__)


class Intake:
    """A bounded queue of ``(t, sensor, sample)`` and the thread feeding them to ``fusion.add`` in stamp order."""

    def __init__(self, fusion, capacity: int = 100_000):
        self.fusion = fusion
        self.capacity = int(capacity)
        self._pending: deque = deque()
        self._cond = threading.Condition()
        self._stop = False
        self.overflow = 0
        self.errors = 0
        self.busy_s = 0.0  # time spent in the fusion's calls
        self._thread = threading.Thread(target=self._run, name="fusion-vo-intake", daemon=True)
        self._thread.start()

    def put(self, t: float, sensor: str, sample) -> None:
        with self._cond:
            if len(self._pending) >= self.capacity:
                self._pending.popleft()
                self.overflow += 1
            self._pending.append((t, sensor, sample))
            self._cond.notify()

    def backlog(self) -> int:
        with self._cond:
            return len(self._pending)

    def stop(self, timeout: float = 1.0) -> None:
        with self._cond:
            self._stop = True
            self._pending.clear()
            self._cond.notify()
        self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._pending and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                batch = list(self._pending)
                self._pending.clear()
            batch.sort(key=lambda item: item[0])
            start = time.perf_counter()
            for _, sensor, sample in batch:
                try:
                    self.fusion.add(sensor, sample)
                except Exception:  # nothing from one sample may stop the intake: logged once, counted
                    self.errors += 1
                    if self.errors == 1:
                        log.exception("a %s sample could not be added to the fusion", sensor)
            self.busy_s += time.perf_counter() - start


class Outputs:
    """One thread running the outputs' work (reading the fusion, publishing) when the timers ask for it.

    A timer callback only calls :meth:`request`; the work, which waits for the fusion's lock while the intake
    or the camera thread holds it, runs here, so the executor thread goes on taking messages meanwhile. A
    task asked for again before it ran runs once.
    """

    def __init__(self, tasks: dict):
        self.tasks = tasks
        self._due: dict = {}
        self._cond = threading.Condition()
        self._stop = False
        self.errors = 0
        self._thread = threading.Thread(target=self._run, name="fusion-vo-outputs", daemon=True)
        self._thread.start()

    def request(self, name: str, *args) -> None:
        with self._cond:
            self._due[name] = args
            self._cond.notify()

    def stop(self, timeout: float = 1.0) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._due and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                due, self._due = self._due, {}
            for name, args in due.items():
                try:
                    self.tasks[name](*args)
                except Exception:  # an output failing once must not end the thread: logged once, counted
                    self.errors += 1
                    if self.errors == 1:
                        log.exception("the node's %s output failed", name)
