"""The measurements a fusion run may use, held by sensor name.

:class:`SensorStreams` has no field of its own for any sensor: the data of every registered sensor, built-in or
not (:mod:`fusion_vo.sensors.registry`), is kept under the sensor's name, and read or set the same way for all::

    streams = SensorStreams(wheel=wheels, imu=imu, compass=CompassData(t, yaw))
    streams["compass"], streams.get("gps"), streams.imu   # data, or None when absent
    streams.replace(imu=None)                              # a copy without the IMU

A sensor may declare a second name its data answers to (:attr:`Sensor.field <fusion_vo.sensors.registry.Sensor.field>`:
the camera's increments are ``visual``). Besides the sensors' data, four facts about the camera travel with the
streams because other sensors' models need them (the range finder, the visual scale's prior): ``camera_height``,
``camera_height_sigma``, ``range_in_visual`` and ``range_height_sigma``.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Iterator, Mapping

from fusion_vo.errors import InputError
from fusion_vo.sensors import registry

#: the facts about the camera the streams carry besides the sensors' data, with their defaults
FACTS = {"camera_height": None, "camera_height_sigma": None, "range_in_visual": False, "range_height_sigma": None}


class SensorStreams:
    """The data of the sensors a fusion run may use, by sensor name (module docstring).

    Parameters
    ----------
    data : mapping, optional
        Sensor name (or a sensor's second name, ``visual``) -> its data (None entries are left out). A name that is
        no registered sensor yet is kept as it is (the data of a sensor registered later).
    camera_height : float, optional
        The height [m] the visual increments were computed with (for the range finder).
    camera_height_sigma : float, optional
        Its standard deviation [m] as ``cam0/sensor.yaml`` states it (``height_sigma``).
    range_in_visual : bool
        The visual increments were already scaled with the range finder's heights (visual odometry's
        ``use_range``): the range finder is then not used again as a height measurement.
    range_height_sigma : float, optional
        With ``range_in_visual``: the typical standard deviation [m] of the heights the frames were scaled with,
        which bounds the prior of the visual scale.
    extra : mapping, optional
        More data by sensor name (the same as ``data``).
    **by_name
        Data by sensor name (``wheel=...``, ``odom1=...``, a registered sensor's name), or by a sensor's second
        name (``visual=...``). A name that is no registered sensor is a TypeError, as a misspelt keyword is.
    """

    def __init__(self, data: Mapping | None = None, *, camera_height: float | None = None,
                 camera_height_sigma: float | None = None, range_in_visual: bool = False,
                 range_height_sigma: float | None = None, extra: Mapping | None = None, **by_name: Any):
        object.__setattr__(self, "_data", {})
        self.camera_height = camera_height
        self.camera_height_sigma = camera_height_sigma
        self.range_in_visual = range_in_visual
        self.range_height_sigma = range_height_sigma
        for key, value in {**dict(data or {}), **dict(extra or {})}.items():
            self.set(key, value)
        for key, value in by_name.items():
            if registry.resolve(key) is None:
                raise TypeError(f"SensorStreams: '{key}' is no sensor (registered: {', '.join(registry.names())})")
            self.set(key, value)

    # ------------------------------------------------------------------ by name
    @staticmethod
    def _name(key: str) -> str:
        """The sensor name ``key`` stands for (itself when it is no registered sensor: data of a sensor to be
        registered later is kept under its own name)."""
        sensor = registry.resolve(key)
        return key if sensor is None else sensor.name

    def get(self, key: str, default: Any = None) -> Any:
        """The data of sensor ``key`` (or its second name), ``default`` when absent."""
        data = self._data
        if key in data:  # (a sensor's own name: asked for at every node)
            return data[key]
        return data.get(self._name(key), default)

    def set(self, key: str, value: Any) -> None:
        """Set the data of sensor ``key`` (None removes it)."""
        name = self._name(key)
        if value is None:
            self._data.pop(name, None)
        else:
            self._data[name] = value

    def __getitem__(self, key: str) -> Any:
        return self._data[self._name(key)]

    def __setitem__(self, key: str, value: Any) -> None:
        self.set(key, value)

    def __contains__(self, key: str) -> bool:
        return self._name(key) in self._data

    def __iter__(self) -> Iterator[str]:
        """The names of the sensors with data, registered ones in the registry's order first."""
        rank = {name: i for i, name in enumerate(registry.names())}
        return iter(sorted(self._data, key=lambda name: rank.get(name, len(rank))))

    def items(self) -> list[tuple[str, Any]]:
        """``(name, data)`` of every sensor with data (:meth:`__iter__` order)."""
        return [(name, self._data[name]) for name in self]

    def __getattr__(self, key: str) -> Any:
        # only reached for names that are not attributes: a sensor's data by name, None when absent
        if key.startswith("_"):
            raise AttributeError(f"'SensorStreams' object has no attribute '{key}'")
        data = self.__dict__.get("_data", {})
        if key in data:
            return data[key]
        if registry.resolve(key) is None:
            raise AttributeError(f"'SensorStreams' object has no attribute '{key}'")
        return self.get(key)

    def __setattr__(self, key: str, value: Any) -> None:
        if key in FACTS:
            object.__setattr__(self, key, value)
        elif registry.resolve(key) is not None:
            self.set(key, value)
        else:
            raise AttributeError(f"SensorStreams: '{key}' is neither a sensor nor one of {', '.join(FACTS)}")

    @property
    def extra(self) -> Mapping:
        """The data of the sensors without a second name (those registered outside the library), by name: a
        read-only view (set a sensor's data with ``streams[name] = data``)."""
        return MappingProxyType({name: data for name, data in self.items()
                                 if (s := registry.resolve(name)) is None or s.field is None})

    # ------------------------------------------------------------------ copies
    def facts(self) -> dict:
        """The camera facts the streams carry (:data:`FACTS`)."""
        return {key: getattr(self, key) for key in FACTS}

    def replace(self, **changes: Any) -> SensorStreams:
        """A copy with ``changes`` (sensors' data by name, None to leave one out, or camera facts); the data
        objects themselves are shared."""
        facts = {key: changes.pop(key) if key in changes else value for key, value in self.facts().items()}
        out = SensorStreams(self._data, **facts)
        for key, value in changes.items():
            if registry.resolve(key) is None and key not in self._data:
                raise TypeError(f"SensorStreams.replace: '{key}' is no sensor")
            out.set(key, value)
        return out

    __replace__ = replace  # copy.replace

    def __repr__(self) -> str:
        return f"SensorStreams({', '.join(self)})"

    # ------------------------------------------------------------------ what the backends ask
    def data(self, sensor: str) -> Any:
        """The data of the registered sensor ``sensor`` (None when absent; KeyError when it is no sensor)."""
        return self._data.get(registry.get(sensor).name)

    def sampled(self) -> list[tuple[str, object]]:
        """``(name, data)`` of every registered sensor's data with per-sample times ``t`` (all but the camera's
        increments)."""
        return [(s.name, self._data[s.name]) for s in registry.sensors() if s.name != "camera" and s.name in self._data]

    def available(self) -> list[str]:
        """Sensor names with enough data to be used."""
        return [s.name for s in registry.sensors() if s.available(self._data.get(s.name))]

    def select(self, sensors) -> SensorStreams:
        """Only the named sensors; a sensor that is asked for but absent is an :class:`InputError`.

        A sensor may answer to another's name (:attr:`Sensor.also_available_as`: ``wheel`` falls back to the
        odometry twist when there are no encoder ticks) and pick its data itself (:attr:`Sensor.pick`).
        """
        sensors = list(sensors)
        registry.ensure(sensors)
        known = registry.names()
        unknown = [s for s in sensors if s not in known]
        if unknown:
            raise InputError(f"unknown sensor '{unknown[0]}' (use {', '.join(known)})")
        available = self.available()
        for s in registry.sensors():
            if s.name in available:
                available += [a for a in s.also_available_as if a not in available]
        missing = [s for s in sensors if s not in available]
        if missing:
            raise InputError(f"sensor '{missing[0]}' was asked for but the recording has no "
                             f"{registry.get(missing[0]).where} data")
        if not sensors:
            raise InputError("no sensors selected")
        out = SensorStreams(**self.facts())
        for s in registry.sensors():
            out.set(s.name, s.pick(self, sensors) if s.pick is not None else (s.data(self) if s.name in sensors else None))
        return out
