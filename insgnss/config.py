"""Job files: one TOML file describes one processing run end to end (schema in docs/jobs.md).

The loader checks every key against a declarative schema (:data:`SCHEMA`) before anything is
read or computed, and every problem is a :class:`~insgnss.errors.ConfigError` that names the
file and the dotted key (``inputs.imu.gyro_unit``):

- **names and types**: an unknown key (a removed one says what replaced it,
  :data:`REMOVED_KEYS`), a value of the wrong type;
- **values**: every key carries a value rule (:class:`Rule`): numbers are finite and inside a
  documented range (standard deviations and intervals > 0, probabilities in [0, 1) where 0 means
  off, ...), vectors have their length (lever arm: three finite numbers), windows are
  ``[start, end]`` pairs with ``start < end``, names come from a closed list;
- **use**: a key the run would not read is an error, never silently ignored (:class:`When`:
  e.g. a key of another input format, the settings of an aiding source that is off, the
  simulation tables of a job that reads recorded data); a setting that needs a companion key
  (``method = "given"`` needs the three angles) is checked here too;
- **against the data** (:func:`check_job_against_data`, once the IMU rate is known and before
  the filter): outage lengths and gaps, ``filter.epoch_interval`` and ``aiding.nhc_interval``
  are at least one IMU interval, ``initialization.start_time`` lies inside the IMU data.

Paths are resolved relative to the job file. Degrees appear only in keys ending in ``_deg``;
everything else is SI.

A job file may also carry simulation tables (``scenario``, ``trajectory``, ``imu``, ``gnss``...)
when it is a scenario for :mod:`insgnss.simulate`; those are validated by the simulator and
passed through here untouched (:data:`SIMULATION_TABLES`). A job *simulates* its data when it
has simulation tables and no ``inputs.imu.path``; it *reads recorded data* otherwise.
"""

from __future__ import annotations

import datetime
import math
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .columns import DEFAULT_OUTPUT_GROUPS, OUTPUT_GROUPS, output_rate
from .errors import ConfigError
from .profiles import DEFAULT_PLATFORM, platforms, profile, profiles_path

_ANY = object()
_NUM = (int, float)


# --- value rules ---------------------------------------------------------------------------------
class Rule:
    """A value rule of the schema.

    ``doc`` is the valid range as docs/jobs.md prints it (a string, or a callable returning
    one, for lists defined elsewhere); ``check(value, key, file)`` returns the normalised value
    or raises :class:`ConfigError` naming ``key``. Numeric rules also carry ``bounds`` =
    ``(lo, hi, lo_open, hi_open)`` (None: unbounded), array rules the ``item`` rule and
    ``length`` (``None``: windows), so that tools can reach the documented extremes
    (bench/bench_extremes.py).
    """

    def __init__(self, doc: str | Callable[[], str], check: Callable[[Any, str, Any], Any], *,
                 bounds: tuple | None = None, item: Rule | None = None, length: int | None = 0):
        self._doc = doc
        self.check = check
        self.bounds = bounds
        self.item = item
        self.length = length

    @property
    def doc(self) -> str:
        return self._doc() if callable(self._doc) else self._doc


def _fail(message: str, key: str, file, expected, found) -> ConfigError:
    return ConfigError(message, file=file, column=key, expected=expected, found=found)


def _is_number(v) -> bool:
    return isinstance(v, _NUM) and not isinstance(v, bool)


def _number(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            hi_open: bool = False, note: str = "") -> Rule:
    """A finite number in ``[lo, hi]`` (open ends as asked); ``note`` documents special values."""
    if lo is not None and hi is not None:
        doc = f"{lo:g} {'<' if lo_open else '<='} x {'<' if hi_open else '<='} {hi:g}"
    elif lo is not None:
        doc = f"{'>' if lo_open else '>='} {lo:g}"
    elif hi is not None:
        doc = f"{'<' if hi_open else '<='} {hi:g}"
    else:
        doc = "finite"
    if note:
        doc += f" ({note})"

    def check(v, key, file):
        x = float(v)
        if not math.isfinite(x):
            raise _fail("not a finite number", key, file, f"a finite number, {doc}", repr(v))
        if (lo is not None and (x < lo or (lo_open and x == lo))) or \
                (hi is not None and (x > hi or (hi_open and x == hi))):
            raise _fail("value out of range", key, file, doc, repr(v))
        return x

    return Rule(doc, check, bounds=(lo, hi, lo_open, hi_open))


FINITE = _number()
POSITIVE = _number(0.0, lo_open=True)
NONNEGATIVE = _number(0.0)


def _vector(n: int, item: Rule = FINITE) -> Rule:
    """An array of exactly ``n`` numbers, each passing ``item``."""
    doc = f"{n} numbers, each {item.doc}" if item is not FINITE else f"{n} finite numbers"

    def check(v, key, file):
        if not isinstance(v, list) or len(v) != n:
            raise _fail("wrong number of elements", key, file, f"an array of {n} numbers",
                        repr(v))
        out = []
        for i, x in enumerate(v):
            if not _is_number(x):
                raise _fail("not a number", key, file, f"an array of {n} numbers",
                            f"element {i + 1} = {x!r}")
            out.append(_value(item, x, key, file, f"element {i + 1}"))
        return out

    return Rule(doc, check, item=item, length=n)


def _windows(unit: str = "s") -> Rule:
    """``[[start, end], ...]``: pairs of finite numbers with ``start < end``."""
    doc = f"[[start, end], ...]: two finite numbers each, start < end [{unit}]"

    def check(v, key, file):
        if not isinstance(v, list):
            raise _fail("not a list of windows", key, file, "[[start, end], ...]", repr(v))
        out = []
        for i, w in enumerate(v):
            if not isinstance(w, list) or len(w) != 2 or not all(_is_number(x) for x in w):
                raise _fail("a window is two numbers [start, end]", key, file, "[start, end]",
                            f"window {i + 1} = {w!r}")
            a, b = float(w[0]), float(w[1])
            if not (math.isfinite(a) and math.isfinite(b)):
                raise _fail("not a finite number", key, file, "finite start and end",
                            f"window {i + 1} = {w!r}")
            if not a < b:
                raise _fail("window ends before it starts", key, file, "start < end",
                            f"window {i + 1} = {w!r}")
            out.append([a, b])
        return out

    return Rule(doc, check, item=FINITE, length=None)


def _integer(lo: int) -> Rule:
    """An integer >= ``lo``."""

    def check(v, key, file):
        if v < lo:
            raise _fail("value out of range", key, file, f"an integer >= {lo}", repr(v))
        return v

    return Rule(f"integer >= {lo}", check, bounds=(lo, None, False, False))


def _integers(lo: int, hi: int) -> Rule:
    """An array of integers in ``[lo, hi]`` (integral floats accepted)."""
    doc = f"integers {lo}-{hi}"

    def check(v, key, file):
        if not isinstance(v, list):
            raise _fail("not an array", key, file, f"an array of {doc}", repr(v))
        out = []
        for x in v:
            if not _is_number(x) or not math.isfinite(float(x)) or float(x) != int(x) \
                    or not lo <= int(x) <= hi:
                raise _fail("invalid element", key, file, doc, repr(x))
            out.append(int(x))
        return out

    return Rule(doc, check)


def _flag_table(value: Rule) -> Rule:
    """``{flag = number}`` with RTKLIB quality flags 1-6 as keys."""
    doc = f"{{flag = multiplier}}: flags 1-6, multipliers {value.doc}"

    def check(v, key, file):
        out = {}
        for k, x in v.items():
            try:
                q = int(k)
            except ValueError:
                q = 0
            if not 1 <= q <= 6:
                raise _fail("invalid RTKLIB quality flag", key, file, "flags 1-6", repr(k))
            if not _is_number(x):
                raise _fail("not a number", key, file, "a number", f"{k} = {x!r}")
            out[str(q)] = _value(value, x, key, file, k)
        return out

    return Rule(doc, check, item=value)


def _value(rule: Rule, x, key, file, element) -> Any:
    try:
        return rule.check(x, key, file)
    except ConfigError as exc:
        raise _fail(exc.message, key, file, exc.expected, f"{element} = {x!r}") from None


def _nonempty(v, key, file):
    if not v.strip():
        raise _fail("empty string", key, file, "a non-empty string", repr(v))
    return v


NONEMPTY = Rule("non-empty", _nonempty)


def _via(doc: str | Callable[[], str], validator: Callable[[Any], Any]) -> Rule:
    """A rule that calls a validator defined next to the code that uses the value (the reader,
    the detector...) and re-labels its error with the job key and file."""

    def check(v, key, file):
        try:
            validator(v)
        except ConfigError as exc:
            msg = exc.message + (f" ({exc.column})" if exc.column and exc.column != key else "")
            raise _fail(msg, key, file, exc.expected, exc.found if exc.found is not None
                        else repr(v)) from None
        except (ValueError, TypeError) as exc:
            raise _fail(str(exc), key, file, None, repr(v)) from None
        return v

    return Rule(doc, check)


def _unit_rule(table: str) -> Rule:
    def names():
        from .io import imu_csv

        return "one of " + ", ".join(getattr(imu_csv, table))

    def validate(v):
        from .io import imu_csv

        imu_csv._choice(v, getattr(imu_csv, table), table.lower())

    return _via(names, validate)


def _grade_names() -> str:
    from .imu import GRADES

    return "one of " + ", ".join(GRADES) + " (any case)"


def _check_grade(v) -> None:
    from .imu import grade

    grade(v)


def _check_axis_map(v) -> None:
    from .io.imu_csv import axis_map_matrix

    axis_map_matrix(v)


def _check_columns(v) -> None:
    from .io.imu_csv import _ALIASES, SLOTS

    for slot, col in v.items():
        if _ALIASES.get(slot, slot) not in SLOTS:
            raise ConfigError("unknown column slot", column=slot, expected=f"one of {SLOTS}",
                              found=repr(slot))
        levels = isinstance(col, list) and col and all(isinstance(c, str) for c in col)
        if not ((isinstance(col, str) and col) or levels or (
                isinstance(col, int) and not isinstance(col, bool) and col >= 0)):
            raise ConfigError("invalid column", column=slot, expected="a column name, a list "
                              "of header levels or a 0-based index", found=repr(col))


def _check_detector(v) -> None:
    from .detect import DetectorConfig

    DetectorConfig.from_dict(v)


def _check_foot(v) -> None:
    from .foot import FootConfig

    FootConfig.from_dict(v)


def _check_date(v) -> None:
    datetime.date.fromisoformat(v)


# --- where a key is read --------------------------------------------------------------------------
class When:
    """The condition under which the run reads a key: ``doc`` (completes "read only when ..."),
    ``test(settings, simulation) -> bool`` (``simulation``: the simulation tables of a job that
    simulates its data, else None) and ``now(settings)``, the present state for messages."""

    def __init__(self, doc: str, test: Callable[[dict, dict | None], bool],
                 now: Callable[[dict], str] | None = None):
        self.doc = doc
        self.test = test
        self.now = now


def _get(settings: dict, dotted: str):
    v: Any = settings
    for part in dotted.split("."):
        v = v[part]
    return v


def _is(key: str, *values) -> When:
    shown = " or ".join(repr(v) for v in values)
    return When(f"{key} = {shown}", lambda s, sim: _get(s, key) in values,
                lambda s: f"{key} = {_get(s, key)!r}")


def _on(*keys: str) -> When:
    return When(" or ".join(f"{k} = true" for k in keys),
                lambda s, sim: any(bool(_get(s, k)) for k in keys))


def _has(key: str) -> When:
    return When(f"{key} is given", lambda s, sim: _get(s, key) is not None)


RECORDED = When("the job reads recorded data (inputs.imu.path); a simulated job takes its data "
                "and the GNSS lever arm from its simulation tables ([gnss] lever_arm)",
                lambda s, sim: sim is None, lambda s: "the job simulates its data")
STANDARD = When("process.preset = 'standard' (the foot preset reads [foot], "
                "initialization.lat_deg/lon_deg/height, filter.coning and the inputs only)",
                lambda s, sim: s["process"]["preset"] == "standard",
                lambda s: f"process.preset = {s['process']['preset']!r}")
HAS_GNSS = When("the job has GNSS data (inputs.gnss.path, inputs.gnss_raw.path, or a "
                "simulated [gnss] table)",
                lambda s, sim: s["inputs"]["gnss"]["path"] is not None
                or s["inputs"]["gnss_raw"]["path"] is not None
                or (sim is not None and "gnss" in sim))
TIGHT = _is("aiding.gnss", "tight")
LOOSE = _is("aiding.gnss", "loose")
ANTENNA = When("inputs.gnss.path or inputs.gnss_raw.path is given",
               lambda s, sim: s["inputs"]["gnss"]["path"] is not None
               or s["inputs"]["gnss_raw"]["path"] is not None)
RAW_GNSS = When("inputs.gnss_raw.path is given",
                lambda s, sim: s["inputs"]["gnss_raw"]["path"] is not None)
CSV, RTKLIBEXPLORER = _is("inputs.imu.format", "csv"), _is("inputs.imu.format", "rtklibexplorer")
CSV_OR_RTKLIBEXPLORER = _is("inputs.imu.format", "csv", "rtklibexplorer")
STATIC = _is("initialization.method", "static")
GIVEN_POSITION = When("process.preset = 'foot', or a job without GNSS data (the start position "
                      "comes from GNSS or the simulated truth otherwise)",
                      lambda s, sim: s["process"]["preset"] == "foot"
                      or (sim is None and s["inputs"]["gnss"]["path"] is None))


def _spec(kind, default=None, doc: str = "", choices=None, check: Rule | None = None,
          when: When | tuple[When, ...] = (), min_imu_intervals: int = 0):
    """One key: type, default, meaning, closed choices, value rule, the conditions under which
    the run reads it, and the IMU intervals it must at least span (checked against the data)."""
    if kind is _NUM and check is None:
        check = FINITE
    return {"type": kind, "default": default, "doc": doc, "choices": choices, "check": check,
            "when": (when,) if isinstance(when, When) else tuple(when),
            "min_imu_intervals": min_imu_intervals}


POSITIVE_SECONDS = _number(0.0, lo_open=True, note="s")

#: names of the self-tuning's parameters (insgnss.job.tuning builds them, docs/filter.md)
AUTOTUNE_PARAMETERS = ("imu_time_offset", "gnss_pos_scale",
                       *(f"gnss_pos_scale_q{q}" for q in range(1, 7)), "gnss_vel_scale",
                       "accel_vrw", "gyro_arw", "accel_bias_instability",
                       "gyro_bias_instability", "nhc_std", "zupt_std")

def _window_end(v, key, file):
    """A processing-window end (insgnss.job.span): a finite number, "+SECONDS" (>= 0) or a
    GPS time "YYYY-MM-DD hh:mm:ss[.fff]"."""
    expected = 'a time [s, job time base], "+SECONDS" or "YYYY-MM-DD hh:mm:ss"'
    if not isinstance(v, str):
        if not math.isfinite(float(v)):
            raise _fail("not a finite number", key, file, expected, repr(v))
        return float(v)
    text = v.strip()
    if text.startswith("+"):
        try:
            x = float(text[1:])
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and x >= 0):
            raise _fail("not a number of seconds", key, file, '"+SECONDS" with SECONDS >= 0',
                        repr(v))
        return text
    try:
        datetime.datetime.fromisoformat(text)
    except ValueError:
        raise _fail("not a time", key, file, expected, repr(v)) from None
    return text


WINDOW_END = Rule('a time [s, job time base], "+SECONDS" after the first IMU sample, or a GPS '
                  'time "YYYY-MM-DD hh:mm:ss"', _window_end)

#: Schema: table -> key -> spec (:func:`_spec`); a dict without a ``"type"`` entry is a
#: sub-table. ``_ANY`` accepts any TOML value.
SCHEMA: dict[str, Any] = {
    "job": {
        "name": _spec(str, "job", "run name used in reports and summary.json"),
        "description": _spec(str, "", "free text, copied to summary.json"),
        "time_base": _spec(str, "unspecified", "time base of every input's time stamps (gps "
                           "seconds, seconds of week, unix_gpst, UTC seconds of day, run: "
                           "seconds from the start of the recording): each reader records the "
                           "base it produced (docs/formats.md) and a different one is an error; "
                           "two inputs in different bases are an error even when unspecified",
                           choices=["gps", "sow", "unix_gpst", "utc_sod", "run",
                                    "unspecified"]),
        "platform": _spec(str, DEFAULT_PLATFORM, "platform profile: the defaults that depend on "
                          "what carries the IMU (insgnss/data/profiles.toml, "
                          "docs/generalization.md); the job's own keys override it",
                          choices=list(platforms())),
        "start": _spec((int, float, str), None, "processing window start: every input is cut "
                       "to the window before anything runs (insgnss.job.span; KF-GINS "
                       "starttime); a GPS time needs time_base gps, sow or unix_gpst",
                       check=WINDOW_END),
        "end": _spec((int, float, str), None, "processing window end (\"+SECONDS\": after the "
                     "first IMU sample, as for start)", check=WINDOW_END),
    },
    "inputs": {
        "imu": {
            "format": _spec(str, "csv", "csv, native, kfgins, rtklibexplorer",
                            choices=["csv", "native", "kfgins", "rtklibexplorer"]),
            "path": _spec(str, None, "IMU file", check=NONEMPTY),
            "tag": _spec(str, None, "RTKLIB .tag file", check=NONEMPTY, when=RTKLIBEXPLORER),
            "columns": _spec(dict, None, "slot -> column name or index", when=CSV,
                             check=_via("slots time, gyro_x..z (or dtheta_x..z), accel_x..z "
                                        "(or dv_x..z); names, header levels or 0-based "
                                        "indices",
                                        _check_columns)),
            "gyro_unit": _spec(str, "rad/s", "gyro unit (rates or increments)", when=CSV,
                               check=_unit_rule("GYRO_UNITS")),
            "accel_unit": _spec(str, "m/s^2", "accelerometer unit (rates or increments)",
                                when=CSV, check=_unit_rule("ACCEL_UNITS")),
            "time_unit": _spec(str, "s", "unit of the time column (sample: a sample index at "
                               "the declared rate_hz)", when=CSV, check=_unit_rule("TIME_UNITS")),
            "time_offset": _spec(_NUM, 0.0, "added to the IMU time [s]",
                                 when=CSV_OR_RTKLIBEXPLORER),
            "estimate_time_offset": _spec(bool, False, "estimate a further IMU-GNSS offset from "
                                          "gyro yaw rate vs GNSS course rate (land vehicles)",
                                          when=HAS_GNSS),
            "time_offset_min_speed": _spec(_NUM, 3.0, "GNSS speed above which the course rate "
                                           "takes part in the time-offset estimate [m/s]",
                                           check=POSITIVE,
                                           when=_on("inputs.imu.estimate_time_offset")),
            "estimate_time_drift": _spec(bool, True, "also estimate a linear drift of the "
                                         "IMU-GNSS offset (the IMU time base's rate error), "
                                         "applied only where the log shows it",
                                         when=_on("inputs.imu.estimate_time_offset")),
            "axis_map": _spec(str, None, 'sensor -> body axis map, e.g. "y,x,-z"', when=CSV,
                              check=_via("three signed distinct axes, a proper rotation",
                                         _check_axis_map)),
            "mounting_deg": _spec(list, None, "sensor mounting roll, pitch, yaw [deg] (the "
                                  "rtklibexplorer format: the data author's passive FRD "
                                  "convention, docs/formats.md)", check=_vector(3),
                                  when=CSV_OR_RTKLIBEXPLORER),
            "mounting_convention": _spec(str, "active", "Euler convention of mounting_deg",
                                         choices=["active", "passive"], when=CSV),
            "sensor_axes": _spec(str, "rfu", "axes of the (mapped) sensor triad",
                                 choices=["rfu", "frd"], when=CSV),
            "rate_hz": _spec(_NUM, None, "declared IMU rate (checked)", check=POSITIVE,
                             when=CSV_OR_RTKLIBEXPLORER),
            "delimiter": _spec(str, ",", "field separator", check=NONEMPTY, when=CSV),
            "header": _spec(bool, True, "the file has a header line", when=CSV),
            "header_rows": _spec(int, 1, "header lines; with more than one a column is named "
                                 "by its levels joined with '_'", check=_integer(1), when=CSV),
            "gap_policy": _spec(str, "error", "gaps longer than max_gap: stop the run, bridge "
                                "them, or process the segments separately (docs/jobs.md, "
                                "Robustness)", choices=["error", "bridge", "split"]),
            "max_gap": _spec(_NUM, 1.0, "longest gap bridged with a warning [s]",
                             check=NONNEGATIVE),
            "gap_noise": _spec(bool, True, "add process noise for the motion missed in bridged "
                               "gaps (rate tables; insgnss.policies.gap_noise)"),
            "duplicates": _spec(str, "drop", "repeated time stamps: drop with a warning (first "
                                "kept) or stop", choices=["drop", "error"]),
            "spike_policy": _spec(str, "off", "single-sample gyro/accelerometer spikes: off, "
                                  "flag (warn and list in the summary) or bridge (also replace "
                                  "each by the mean of its neighbours; docs/jobs.md, "
                                  "Robustness)", choices=["off", "flag", "bridge"]),
        },
        "gnss": {
            "format": _spec(str, "rtklib_pos", "GNSS file format",
                            choices=["rtklib_pos", "nmea", "kfgins", "native"]),
            "path": _spec(str, None, "GNSS file", check=NONEMPTY),
            "lever_arm": _spec(list, [0.0, 0.0, 0.0], "IMU -> antenna, body RFU [m]",
                               check=_vector(3)),
            "time_offset": _spec(_NUM, 0.0, "added to the GNSS time [s]"),
            "estimate_velocity_lag": _spec(bool, True, "estimate how far the velocity time tags "
                                           "lag the positions (receivers that difference "
                                           "positions tag the mean velocity at the interval end)"
                                           " and move the velocities to their time",
                                           when=_on("aiding.gnss_velocity")),
            "date": _spec(str, None, "date for NMEA without RMC (YYYY-MM-DD)",
                          check=_via("YYYY-MM-DD", _check_date), when=_is("inputs.gnss.format",
                                                                          "nmea")),
            "duplicates": _spec(str, "drop", "repeated epochs: drop with a warning (first kept) "
                                "or stop", choices=["drop", "error"]),
        },
        "gnss_raw": {
            "format": _spec(str, "ubx", "raw receiver observations: ubx (u-blox RXM-RAWX + "
                            "RXM-SFRBX stream) or rinex (RINEX 3 observation file with "
                            "nav_path); docs/tight.md", choices=["ubx", "rinex"]),
            "path": _spec(str, None, "raw GNSS file (without inputs.gnss.path its single-point "
                          "solution is the GNSS table of the job)", check=NONEMPTY),
            "nav_path": _spec(str, None, "RINEX 3 navigation file", check=NONEMPTY,
                              when=_is("inputs.gnss_raw.format", "rinex")),
            "elevation_mask_deg": _spec(_NUM, 10.0, "satellites below are not used [deg]",
                                        check=_number(0.0, 90.0, hi_open=True), when=RAW_GNSS),
            "cn0_mask": _spec(_NUM, 25.0, "signals below this C/N0 are not used [dB-Hz]",
                              check=_number(0.0, 60.0), when=RAW_GNSS),
        },
        "odometer": {
            "format": _spec(str, "native", "native (time, speed [m/s] or distance [m]) or csv "
                            "(declared unit)", choices=["native", "csv"]),
            "path": _spec(str, None, "odometer file", check=NONEMPTY),
            "kind": _spec(str, "speed", "what the value column holds",
                          choices=["speed", "distance"]),
            "unit": _spec(str, None, "unit of the csv format: speed m/s, km/h, mph, knots; "
                          "distance m, km, ft", choices=["m/s", "km/h", "mph", "knots", "m", "km",
                                                         "ft"],
                          when=_is("inputs.odometer.format", "csv")),
            "time_offset": _spec(_NUM, 0.0, "added to the odometer time [s]"),
        },
        "reference": {
            "format": _spec(str, "rtklib_pos", "reference file format",
                            choices=["rtklib_pos", "kfgins_nav", "native"]),
            "path": _spec(str, None, "reference trajectory file", check=NONEMPTY),
            "point": _spec(str, "antenna", "which point the reference measures",
                           choices=["antenna", "imu"]),
            "q": _spec(list, None, "keep only these RTKLIB quality flags (e.g. [1])",
                       check=_integers(1, 6), when=_is("inputs.reference.format", "rtklib_pos")),
        },
        "control_points": {
            "path": _spec(str, None, "CUPT points: native CSV time, lat_deg, lon_deg, height",
                          check=NONEMPTY),
            "std": _spec(_NUM, 0.02, "default point sigma [m]", check=POSITIVE),
        },
    },
    "process": {
        "preset": _spec(str, "standard", "standard: the error-state filter with the aiding "
                        "below; foot: foot-mounted pedestrian ZUPT/ZARU INS ([foot] table, "
                        "docs/zupt.md)", choices=["standard", "foot"]),
    },
    "foot": _spec(dict, {}, "foot-mounted settings (insgnss.foot.FootConfig fields, with a "
                  "[foot.detector] sub-table)", check=_via("FootConfig fields", _check_foot),
                  when=_is("process.preset", "foot")),
    "initialization": {
        "lat_deg": _spec(_NUM, None, "given start latitude", check=_number(-90.0, 90.0),
                         when=GIVEN_POSITION),
        "lon_deg": _spec(_NUM, None, "given start longitude", check=_number(-180.0, 360.0),
                         when=GIVEN_POSITION),
        "height": _spec(_NUM, None, "given start ellipsoidal height [m]",
                        check=_number(-1.2e4, 1e8), when=GIVEN_POSITION),
        "method": _spec(str, "static", "static, gnss_velocity or given",
                        choices=["static", "gnss_velocity", "given"]),
        "static_duration": _spec(_NUM, None, "static window at the start [s] (default: the "
                                 "initial still period found in the data)",
                                 check=POSITIVE, when=STATIC, min_imu_intervals=2),
        "static_max_accel_std": _spec(_NUM, 0.5, "stillness limit of the static window "
                                      "(specific-force variation, m/s^2; engine vibration)",
                                      check=POSITIVE, when=STATIC),
        "static_max_rate_std_deg": _spec(_NUM, 5.0, "stillness limit of the static window "
                                         "(angular-rate variation, deg/s)", check=POSITIVE,
                                         when=STATIC),
        "heading_deg": _spec(_NUM, None, "given heading (static with an IMU that cannot "
                             "gyrocompass, or given)", check=_number(-360.0, 360.0),
                             when=_is("initialization.method", "static", "given")),
        "roll_deg": _spec(_NUM, None, "given roll", check=_number(-180.0, 180.0),
                          when=_is("initialization.method", "given", "gnss_velocity")),
        "pitch_deg": _spec(_NUM, None, "given pitch", check=_number(-90.0, 90.0),
                           when=_is("initialization.method", "given", "gnss_velocity")),
        "velocity": _spec(list, None, "given initial velocity east, north, up [m/s] "
                          "(default: at rest)", check=_vector(3),
                          when=_is("initialization.method", "given")),
        "min_speed": _spec(_NUM, 3.0, "speed for GNSS-velocity heading [m/s]", check=POSITIVE,
                           when=_is("initialization.method", "static", "gnss_velocity")),
        "course_heading_std_deg": _spec(_NUM, 3.0, "heading sigma when the heading comes from "
                                        "the course over ground (how well the IMU's forward "
                                        "axis follows the direction of travel) [deg]",
                                        check=_number(0.0, 180.0, lo_open=True),
                                        when=_is("initialization.method", "static",
                                                 "gnss_velocity")),
        "heading_alignment": _spec(str, "course", "static start without gyrocompassing: "
                                   "heading from the GNSS course (course) or from matching a "
                                   "free-inertial run to the GNSS displacements after the "
                                   "static window (in_motion, falls back to the course)",
                                   choices=["course", "in_motion"], when=STATIC),
        "start_time": _spec(_NUM, None, "start processing here [s, job time base]; inside the "
                            "IMU data"),
        "position_std": _spec(_NUM, None, "initial position sigma [m] (default: GNSS)",
                              check=POSITIVE),
        "velocity_std": _spec(_NUM, None, "initial velocity sigma [m/s] (default: 0.02 static, "
                              "0.2 gnss_velocity, 0.1 given)", check=POSITIVE),
        "attitude_std_deg": _spec(list, None, "initial roll, pitch, heading sigma [deg] "
                                  "(default: from the initialization method)",
                                  check=_vector(3, _number(0.0, 180.0, lo_open=True))),
    },
    "aiding": {
        "gnss": _spec(str, "loose", "GNSS coupling: loose (position/velocity fixes of "
                      "inputs.gnss) or tight (a pseudorange and a Doppler update per "
                      "satellite from inputs.gnss_raw, receiver clock states; docs/tight.md)",
                      choices=["loose", "tight"], when=HAS_GNSS),
        "doppler": _spec(bool, True, "tight coupling: Doppler range-rate updates beside the "
                         "pseudoranges", when=TIGHT),
        "gnss_position": _spec(bool, True, "GNSS position updates"),
        "gnss_velocity": _spec(bool, False, "GNSS velocity updates"),
        "gnss_position_std": _spec(_NUM, None, "override per-epoch std [m]", check=POSITIVE,
                                   when=_on("aiding.gnss_position")),
        "gnss_velocity_std": _spec(_NUM, None, "override per-epoch std [m/s]", check=POSITIVE,
                                   when=_on("aiding.gnss_velocity")),
        "gnss_velocity_std_scale": _spec(_NUM, 1.0, "multiplies the file's velocity std (after "
                                         "q_scale)", check=POSITIVE,
                                         when=_on("aiding.gnss_velocity")),
        "gnss_std_scale": _spec(_NUM, 1.0, "multiplies the file's std", check=POSITIVE,
                                when=_on("aiding.gnss_position")),
        "gnss_min_std": _spec(_NUM, 0.005, "floor of the position std [m] (0: no floor)",
                              check=NONNEGATIVE, when=_on("aiding.gnss_position")),
        "q_scale": _spec(dict, {"1": 1.0, "2": 3.0, "3": 1.0, "4": 1.0, "5": 1.0, "6": 1.0},
                         "std multiplier per RTKLIB Q flag (1 fix, 2 float, 3 SBAS, 4 DGPS, "
                         "5 single, 6 PPP; a flag not listed drops its epochs); float "
                         "solutions' std are optimistic", check=_flag_table(POSITIVE),
                         when=_on("aiding.gnss_position", "aiding.gnss_velocity")),
        "zupt": _spec(bool, False, "zero-velocity updates while still"),
        "zaru": _spec(bool, False, "zero-angular-rate updates while still"),
        "zupt_std": _spec(_NUM, 0.02, "ZUPT velocity sigma [m/s]", check=POSITIVE,
                          when=_on("aiding.zupt")),
        "zupt_interval": _spec(_NUM, 0.1, "ZUPT/ZARU update interval during stillness [s]",
                               check=POSITIVE, when=_on("aiding.zupt", "aiding.zaru")),
        "zupt_max_speed": _spec(_NUM, 1.0, "apply ZUPT/ZARU only below this nominal speed "
                                "[m/s] (0: always; vehicles at constant speed look still)",
                                check=NONNEGATIVE,
                                when=When("aiding.zupt or aiding.zaru = true (or "
                                          "aiding.detector is given, for insgnss compare)",
                                          lambda s, sim: s["aiding"]["zupt"] or
                                          s["aiding"]["zaru"] or bool(s["aiding"]["detector"]))),
        "zupt_threshold_from_static": _spec(bool, False, "default detector (no "
                                            "aiding.detector): threshold from the still noise "
                                            "of the static start window (docs/zupt.md)",
                                            when=_on("aiding.zupt", "aiding.zaru")),
        "detector": _spec(dict, {}, "stillness detector settings (docs/zupt.md; also used by "
                          "insgnss compare)",
                          check=_via("DetectorConfig fields", _check_detector)),
        "static_intervals": _spec(list, None, "declared still intervals [[t0, t1], ...] (also "
                                  "used by insgnss compare)", check=_windows()),
        "nhc": _spec(bool, False, "non-holonomic constraint (land vehicles)"),
        "heading_reinit": _spec(bool, False, "land vehicle: re-initialise the heading (and "
                                "horizontal velocity) from the GNSS course when the forward "
                                "axis disagrees with it while the GNSS innovations are large "
                                "(strapdown, LLF frame; docs/filter.md)", when=HAS_GNSS),
        "heading_reinit_angle_deg": _spec(_NUM, 30.0, "heading-course disagreement that counts "
                                          "[deg]", check=_number(5.0, 180.0),
                                          when=_on("aiding.heading_reinit")),
        "heading_reinit_duration": _spec(_NUM, 3.0, "how long the disagreement must last [s]",
                                         check=POSITIVE, when=_on("aiding.heading_reinit")),
        "heading_reinit_min_speed": _spec(_NUM, 5.0, "GNSS speed above which the course counts "
                                          "[m/s] (reversing is slower)", check=POSITIVE,
                                          when=_on("aiding.heading_reinit")),
        "nhc_std": _spec(list, [0.1, 0.1], "lateral, vertical body velocity sigma [m/s]",
                         check=_vector(2, POSITIVE), when=_on("aiding.nhc")),
        "nhc_interval": _spec(_NUM, 0.25, "NHC update interval [s]: the constraint's violations "
                              "(suspension, vibration, slip) are correlated in time, so faster "
                              "updates over-weight it; each update is placed on a GNSS (odometer, ...) "
                              "epoch closer than half the interval, where there is one",
                              check=POSITIVE, when=_on("aiding.nhc"),
                              min_imu_intervals=1),
        "nhc_correlation_time": _spec(_NUM, 0.0, "correlation time of the NHC's violations "
                                      "(side slip, suspension heave) [s]: > 0 models them as a "
                                      "Gauss-Markov state per axis with sigma aiding.nhc_std, "
                                      "and aiding.nhc_white_std is the white part (strapdown "
                                      "process model; 0: white, sigma aiding.nhc_std)",
                                      check=NONNEGATIVE, when=_on("aiding.nhc")),
        "nhc_white_std": _spec(list, [0.02, 0.02], "white part of the NHC's lateral, vertical "
                               "violation (vibration at the IMU) [m/s], with "
                               "aiding.nhc_correlation_time > 0", check=_vector(2, POSITIVE),
                               when=_on("aiding.nhc")),
        "nhc_violation_from_data": _spec(bool, False, "measure the NHC's violations (sigma per "
                                         "axis, correlation time) in the smoothed body-frame "
                                         "velocity of a first pass outside the outages and run "
                                         "again with them as Gauss-Markov states "
                                         "(aiding.nhc_std, aiding.nhc_correlation_time; "
                                         "strapdown)",
                                         when=(_on("aiding.nhc"), _on("filter.smoother"))),
        "nhc_misalignment": _spec(bool, False, "estimate the residual IMU-to-vehicle pitch/yaw "
                                  "misalignment in the NHC (strapdown process model)",
                                  when=_on("aiding.nhc")),
        "nhc_pitch_compliance": _spec(bool, False, "estimate the suspension's pitch per unit "
                                      "forward acceleration (squat/dive) in the vertical NHC "
                                      "(strapdown process model)",
                                      when=_on("aiding.nhc")),
        "nhc_lever_arm": _spec(list, [0.0, 0.0, 0.0], "IMU -> rear-axle centre (the point "
                               "without lateral velocity), body RFU [m]", check=_vector(3),
                               when=_on("aiding.nhc")),
        "nhc_slip_gradient": _spec(_NUM, 0.0, "tyre slip angle per lateral acceleration "
                                   "[rad/(m/s^2)], about 0.01 for a passenger car: the lateral "
                                   "NHC sigma grows to sqrt(std^2 + (k yaw_rate speed^2)^2) in "
                                   "turns (0: constant)",
                                   check=NONNEGATIVE, when=_on("aiding.nhc")),
        "cupt": _spec(bool, False, "control-point updates (inputs.control_points)"),
        "odometer": _spec(bool, False, "odometer speed updates"),
        "odometer_std": _spec(_NUM, 0.1, "odometer speed sigma [m/s]", check=POSITIVE,
                              when=When("aiding.odometer = true or filter.process_model = "
                                        "'riss'", lambda s, sim: s["aiding"]["odometer"]
                                        or s["filter"]["process_model"] == "riss")),
    },
    "outages": {
        "windows": _spec(list, [], "explicit [[start, end], ...] [s, job time base]",
                         check=_windows(), min_imu_intervals=1),
        "relative_to": _spec(str, "first_gnss", "time origin of the windows",
                             choices=["first_gnss", "absolute"],
                             when=When("outages.windows is given",
                                       lambda s, sim: bool(s["outages"]["windows"]))),
        "keep_satellites": _spec(int, 0, "tight coupling: inside the windows keep the N "
                                 "highest satellites of each epoch instead of none (partial "
                                 "outages)", check=_integer(0), when=TIGHT),
        "periodic": {
            "start": _spec(_NUM, None, "first outage start after the first GNSS epoch [s]",
                           check=NONNEGATIVE),
            "length": _spec(_NUM, None, "outage length [s]", check=POSITIVE,
                            min_imu_intervals=1),
            "gap": _spec(_NUM, None, "GNSS time between outages [s]", check=POSITIVE,
                         min_imu_intervals=1),
            "stop_before_end": _spec(_NUM, 0.0, "no outage starts later than this before the "
                                     "end [s]", check=NONNEGATIVE,
                                     when=_has("outages.periodic.length")),
        },
    },
    "filter": {
        "process_model": _spec(str, "strapdown", "process model",
                               choices=["strapdown", "riss"]),
        "frame": _spec(str, "enu", "navigation frame of the strapdown process model: local-level "
                       "ENU, or wander azimuth with ECEF errors (valid over the poles; no "
                       "high-rate path; docs/filter.md)", choices=["enu", "wander"],
                       when=_is("filter.process_model", "strapdown")),
        "propagation_interval": _spec(_NUM, 0.1, "covariance propagation step [s] (shorter "
                                      "than an IMU interval: every sample)", check=POSITIVE),
        "epoch_interval": _spec(_NUM, 1.0, "longest filter step without a measurement [s]: a "
                                "grid of epochs (smoother nodes) where the measurement epochs "
                                "are further apart", check=POSITIVE, min_imu_intervals=1),
        "epoch_grid": _spec(str, "gaps", "where the epoch_interval grid is laid: 'gaps' (only "
                            "between measurement epochs further apart than the interval) or "
                            "'always' (every grid time is a node: P(k|k), P(k|N) on the grid; "
                            "a Monte Carlo run takes it unless the job sets it)",
                            choices=["gaps", "always"]),
        "discretization": _spec(str, "second_order", "Phi/Qd discretization",
                                choices=["second_order", "vanloan"]),
        "kalman": _spec(str, "compiled", "Kalman predict/update of the GNSS and other general "
                        "epochs: compiled, or filterpy's (the reference, for checking; "
                        "docs/filter.md)", choices=["compiled", "filterpy"]),
        "gate_probability": _spec(_NUM, 0.9999, "chi-square gate of every measurement",
                                  check=_number(0.0, 1.0, hi_open=True, note="0: off")),
        "gate_recovery": _spec(_NUM, 5.0, "after this many seconds of continuous rejection of "
                               "one measurement type the covariance is inflated and the "
                               "measurement accepted [s]", check=_number(0.0, note="0: never")),
        "nis_window": _spec(_NUM, 30.0, "runaway-NIS check window [s]",
                            check=_number(0.0, note="0: off")),
        "nis_bound": _spec(_NUM, 25.0, "stop when the window median of NIS/dof of one "
                           "measurement type exceeds this", check=POSITIVE,
                           when=When("filter.nis_window > 0",
                                     lambda s, sim: s["filter"]["nis_window"] > 0)),
        "bias_model": _spec(str, "random_walk", "random_walk: turn-on bias + random walk "
                            "from the instability (robust); gauss_markov: the whole bias is a "
                            "zero-mean first-order GM process (only after a calibration removed "
                            "the turn-on bias)",
                            choices=["gauss_markov", "random_walk", "random_constant"]),
        "scale_factors": _spec(bool, False, "estimate IMU scale factors"),
        "smoother": _spec(bool, True, "RTS smoother after the forward filter"),
        "smoother_passes": _spec(int, 1, "passes of filter and smoother (strapdown): 2 runs "
                                 "the filter again from the first pass's smoothed start state "
                                 "and parameter states (re-linearized; prior sigmas kept), "
                                 "which makes the forward solution non-causal",
                                 check=_integer(1), when=_on("filter.smoother")),
        "store_memory_mb": _spec(_NUM, 64.0, "memory [MiB] for the engine's stored arrays (the "
                                 "smoother's per-epoch store, the IMU-rate forward and smoothed "
                                 "tables) and, counted apart, for the long input arrays (IMU "
                                 "triads, a native reference); beyond it they are memory-mapped "
                                 "in the output folder (or the temporary folder) and read in "
                                 "blocks, same numbers",
                                 check=_number(1.0, 1.0e7)),
        "coning": _spec(bool, False, "two-sample coning/sculling correction of the increments "
                        "(strapdown and foot; for integrated increments, not for the exact "
                        "duals a simulation makes)"),
        "levelling_correlation": _spec(bool, False, "static initialization: correlate the "
                                       "levelled tilt with the accelerometer-bias states in P0 "
                                       "(FilterConfig.levelling_correlation; experimental)",
                                       when=STATIC),
        "vibration_noise": _spec(bool, True, "add the vibration measured in the quiet "
                                 "windows (a vehicle standing with the engine running) above "
                                 "ARW/VRW as process noise there (insgnss.preprocess."
                                 "vibration_noise, docs/filter.md)"),
        "noise_from_static": _spec(bool, False, "raise ARW/VRW to the noise measured in the "
                                   "static initialization window (vibration)", when=STATIC),
        "imu_grade": _spec(str, None, "IMU error model for the filter (default: the "
                           "scenario's [imu] for simulated jobs, else tactical)",
                           check=_via(_grade_names, _check_grade)),
        "autotune": _spec(bool, False, "estimate the noise parameters that matter most from the "
                          "data by maximum likelihood (insgnss.autotune, docs/filter.md)",
                          when=_is("filter.process_model", "strapdown")),
        "autotune_sweeps": _spec(int, 2, "coordinate sweeps of the self-tuning",
                                 check=_integer(1), when=_on("filter.autotune")),
        "autotune_parameters": _spec(list, None, "parameters the self-tuning estimates "
                                     "(default: every one the job's aiding can inform except "
                                     "nhc_std, which is estimated only when named; "
                                     "docs/filter.md)", choices=list(AUTOTUNE_PARAMETERS),
                                     when=_on("filter.autotune")),
        "riss": {
            "odometer_scale_std": _spec(_NUM, 0.02, "RISS: initial odometer scale-factor sigma",
                                        check=NONNEGATIVE),
            "odometer_scale_psd": _spec(_NUM, 0.0, "RISS: its random-walk PSD [1/s]",
                                        check=NONNEGATIVE),
            "slip_std": _spec(_NUM, 0.02, "RISS: wheel slip / speed model sigma [m/s]",
                              check=POSITIVE),
            "split_turn_on": _spec(bool, True, "RISS: separate random-constant turn-on biases"),
            "azimuth": _spec(str, "exact", "RISS azimuth equation (docs/riss.md)",
                             choices=["exact", "level", "projected"]),
            "coriolis": _spec(bool, True, "RISS: Earth-rate / Coriolis terms"),
            "window": _spec(_NUM, 1.0, "RISS: pitch/roll smoothing window [s]", check=POSITIVE),
        },
        "imu_model": {
            "gyro_bias_deg_h": _spec(_NUM, None, "overrides of the grade, datasheet units: "
                                     "turn-on gyro bias [deg/h] (the initial sigma of an "
                                     "estimated state, so > 0)", check=POSITIVE),
            "accel_bias_mg": _spec(_NUM, None, "turn-on accelerometer bias [mg]",
                                   check=POSITIVE),
            "gyro_bias_instability_deg_h": _spec(_NUM, None, "[deg/h] (0: a constant bias)",
                                                 check=NONNEGATIVE),
            "accel_bias_instability_ug": _spec(_NUM, None, "[ug] (0: a constant bias)",
                                               check=NONNEGATIVE),
            "bias_correlation_time_s": _spec(_NUM, None, "[s]", check=POSITIVE),
            "gyro_arw_deg_sqrt_h": _spec(_NUM, None, "angle random walk [deg/sqrt(h)]",
                                         check=POSITIVE),
            "accel_vrw_m_s_sqrt_h": _spec(_NUM, None, "velocity random walk [m/s/sqrt(h)]",
                                          check=POSITIVE),
            "gyro_scale_ppm": _spec(_NUM, None, "initial sigma of the estimated gyro scale "
                                    "factors [ppm]", check=POSITIVE,
                                    when=_on("filter.scale_factors")),
            "accel_scale_ppm": _spec(_NUM, None, "initial sigma of the estimated "
                                     "accelerometer scale factors [ppm]", check=POSITIVE,
                                     when=(_on("filter.scale_factors"),
                                           _is("filter.process_model", "strapdown"))),
        },
    },
    "evaluation": {
        "enabled": _spec(bool, True, "evaluate against the reference (or simulated truth)"),
        "settle_time": _spec(_NUM, 10.0, "ignore the first seconds [s]", check=NONNEGATIVE,
                             when=_on("evaluation.enabled")),
        "guard_time": _spec(_NUM, 1.0, "skip after each outage end in the non-outage RMS [s]",
                            check=NONNEGATIVE, when=_on("evaluation.enabled")),
    },
    "outputs": {
        "dir": _spec(str, "out", "output folder (relative to the job file)", check=NONEMPTY),
        "report": _spec(bool, True, "write report.html"),
        "formats": _spec(list, ["csv"], "trajectory formats: csv, parquet (the same columns, "
                         "binary), nav (KF-GINS text), kml, geojson, eval (scorer CSV)",
                         choices=["csv", "parquet", "nav", "kml", "geojson", "eval"]),
        "columns": _spec(list, list(DEFAULT_OUTPUT_GROUPS), "trajectory column groups: nav, "
                         "std (their sigmas), params (biases, scale factors, extra states and "
                         "their sigmas), all (insgnss.columns)", choices=list(OUTPUT_GROUPS)),
        "rate_hz": _spec((int, float, str), "auto", 'trajectory rate [Hz], "imu" (every '
                         'sample) or "auto" (10 Hz; every sample with the foot preset); the '
                         "samples around each GNSS and control-point epoch are always kept "
                         "(insgnss.columns)",
                         check=_via('a positive number [Hz], "imu" or "auto"', output_rate)),
        "figures": _spec(list, [], "report figures also written as fig_<name>.<ext> beside "
                         "the report", choices=["png", "pdf", "svg"],
                         when=_on("outputs.report")),
        "point": _spec(str, "imu", "trajectory point written: imu or antenna",
                       choices=["imu", "antenna"]),
        "progress": _spec(bool, True, "progress bar"),
    },
}

#: keys of earlier versions: dotted key -> what to do instead (the loader says so)
REMOVED_KEYS = {
    "inputs.gnss.use_velocity": "use aiding.gnss_velocity (GNSS velocity updates); this key "
                                "was never read",
    "aiding.nhc_min_speed": "NHC applies at every speed (a land vehicle's lateral and vertical "
                            "velocity are zero at standstill too); this key was never read",
}

#: top-level tables that belong to the simulator (validated by insgnss.simulate; the same names
#: as insgnss.simulate.scenario.SIM_TABLES) and to Monte Carlo runs
SIMULATION_TABLES = ("scenario", "trajectory", "imu", "gnss", "odometer", "magnetometer",
                     "montecarlo")


def _finish_schema() -> None:
    """Conditions shared by whole tables (one place instead of on every key)."""
    reader_keys = {"format", "path", "tag", "columns", "gyro_unit", "accel_unit", "time_unit",
                   "time_offset", "axis_map", "mounting_deg", "mounting_convention",
                   "sensor_axes", "rate_hz", "delimiter", "header", "header_rows"}
    for key, spec in iter_schema():
        parts = key.split(".")
        extra: list[When] = []
        if parts[0] == "inputs":
            if parts[1] != "imu" or parts[2] in reader_keys:
                extra.append(RECORDED)  # a simulated job reads none of these
            if key == "inputs.gnss.lever_arm":
                extra.append(ANTENNA)  # the antenna of either GNSS input
            elif parts[1] != "imu" and parts[2] != "path":
                extra.append(_has(f"inputs.{parts[1]}.path"))
        if (parts[0] in ("aiding", "filter") and key != "filter.coning") or \
                (parts[0] == "initialization" and spec["when"][:1] != (GIVEN_POSITION,)):
            extra.append(STANDARD)
        if parts[:2] == ["filter", "riss"]:
            extra.append(_is("filter.process_model", "riss"))
        if parts[0] == "aiding" and (parts[1].startswith("gnss_") or parts[1] == "q_scale"):
            extra.append(LOOSE)  # the fixes of inputs.gnss; tight coupling reads none
        spec["when"] = tuple(extra) + spec["when"]


def iter_schema(schema: dict | None = None, prefix: str = "") -> Iterator[tuple[str, dict]]:
    """``(dotted key, spec)`` of every key of the schema."""
    for key, spec in (SCHEMA if schema is None else schema).items():
        if _is_table_spec(spec):
            yield from iter_schema(spec, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", spec


def _type_name(kind) -> str:
    if kind is _NUM:
        return "number"
    if isinstance(kind, tuple):
        return " or ".join(k.__name__ for k in kind)
    return {str: "string", bool: "boolean", int: "integer", list: "array",
            dict: "table"}.get(kind, str(kind))


def _check_value(value, spec, key: str, file) -> Any:
    kind = spec["type"]
    if kind is _ANY:
        return value
    ok = isinstance(value, kind) and not (kind in (_NUM, int) and isinstance(value, bool))
    if not ok:
        raise ConfigError("wrong type", file=file, column=key, expected=_type_name(kind),
                          found=f"{type(value).__name__} {value!r}")
    if spec["choices"] is not None and kind is list:  # a list of choices
        bad = [v for v in value if v not in spec["choices"]]
        if bad:
            raise ConfigError("value not allowed", file=file, column=key,
                              expected=f"some of {spec['choices']}", found=repr(bad))
    elif spec["choices"] is not None and value not in spec["choices"]:
        raise ConfigError("value not allowed", file=file, column=key,
                          expected=f"one of {spec['choices']}", found=repr(value))
    if spec["check"] is not None:
        value = spec["check"].check(value, key, file)
    return float(value) if kind is _NUM else value


def _is_table_spec(spec) -> bool:
    return isinstance(spec, dict) and "type" not in spec


def _validate(table: dict, schema: dict, prefix: str, file, given: set,
              defaults: bool = True) -> dict:
    out: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if key not in schema:
            if dotted in REMOVED_KEYS:
                raise ConfigError(f"removed key: {REMOVED_KEYS[dotted]}", file=file,
                                  column=dotted)
            raise ConfigError("unknown key", file=file, column=dotted,
                              expected=f"one of {sorted(schema)}", found=repr(key))
        spec = schema[key]
        if _is_table_spec(spec):
            if not isinstance(value, dict):
                raise ConfigError("wrong type", file=file, column=dotted, expected="table",
                                  found=type(value).__name__)
            out[key] = _validate(value, spec, dotted + ".", file, given, defaults)
        else:
            out[key] = _check_value(value, spec, dotted, file)
            given.add(dotted)
    if not defaults:
        return out
    for key, spec in schema.items():  # defaults
        if key in out:
            continue
        out[key] = _validate({}, spec, f"{prefix}{key}.", file, given) \
            if _is_table_spec(spec) else spec["default"]
    return out


def _check_use(settings: dict, given: set, simulation: dict, file) -> None:
    """A key the run would not read is an error (each spec's ``when``), and the combinations
    the run needs are present."""
    recorded = settings["inputs"]["imu"]["path"] is not None
    sim = simulation if simulation and not recorded else None
    if recorded and simulation:
        name = sorted(simulation)[0]
        raise ConfigError(
            f"simulation table [{name}] in a job that reads recorded data (inputs.imu.path) and "
            "does not simulate: the run would ignore the table"
            + ("; the GNSS antenna lever arm of recorded data is inputs.gnss.lever_arm"
               if "gnss" in simulation else ""),
            file=file, column=name, expected="no simulation tables, or no inputs.imu.path",
            found=f"[{'], ['.join(sorted(simulation))}]")
    for key, spec in iter_schema():
        if key not in given:
            continue
        for cond in spec["when"]:
            if not cond.test(settings, sim):
                here = f" (here {cond.now(settings)})" if cond.now else ""
                raise ConfigError(f"{key} is not used by this job: it is read only when "
                                  f"{cond.doc}{here}", file=file, column=key,
                                  found=repr(_get(settings, key)))

    def need(key: str, why: str) -> None:
        if _get(settings, key) is None:
            raise ConfigError(f"missing setting: {why}", file=file, column=key)

    per = settings["outages"]["periodic"]
    if any(per[k] is not None for k in ("start", "length", "gap")):
        for k in ("start", "length", "gap"):
            need(f"outages.periodic.{k}", "periodic outages need start, length and gap")
    ini = settings["initialization"]
    if settings["process"]["preset"] == "standard" and ini["method"] == "given":
        for k in ("roll_deg", "pitch_deg", "heading_deg"):
            need(f"initialization.{k}", "method = 'given' needs roll_deg, pitch_deg and "
                                        "heading_deg")
    if recorded and settings["inputs"]["imu"]["format"] == "rtklibexplorer":
        need("inputs.imu.mounting_deg", "the rtklibexplorer format needs the declared mounting")
    if recorded and settings["inputs"]["imu"]["format"] == "csv" and \
            settings["inputs"]["imu"]["time_unit"] == "sample":
        need("inputs.imu.rate_hz", "time_unit = 'sample' needs the declared rate")
    a, f = settings["aiding"], settings["filter"]
    if settings["process"]["preset"] != "standard":
        return
    if a["cupt"]:
        if sim is not None:
            raise ConfigError("CUPT needs surveyed control points (inputs.control_points.path, "
                              "recorded data); insgnss compare simulates them for a scenario",
                              file=file, column="aiding.cupt")
        need("inputs.control_points.path", "aiding.cupt needs control points")
    if a["odometer"] and f["process_model"] == "riss":
        raise ConfigError("with process_model = 'riss' the odometer is the process input; "
                          "switch aiding.odometer off", file=file, column="aiding.odometer")
    if a["odometer"] or f["process_model"] == "riss":
        what = "aiding.odometer" if a["odometer"] else "filter.process_model = 'riss'"
        if sim is not None and "odometer" not in sim:
            raise ConfigError(f"{what} needs odometer data: an [odometer] simulation table",
                              file=file, column="odometer")
        if sim is None:
            need("inputs.odometer.path", f"{what} needs odometer data")


def _overlay(base: dict, top: dict, schema: dict) -> dict:
    """``top`` over ``base`` key by key, descending into the schema's tables (a table-valued
    key such as ``aiding.q_scale`` is one value: ``top``'s replaces ``base``'s)."""
    out = dict(base)
    for key, value in top.items():
        spec = schema.get(key)
        if spec is not None and _is_table_spec(spec) and isinstance(value, dict) \
                and isinstance(out.get(key), dict):
            out[key] = _overlay(out[key], value, spec)
        else:
            out[key] = value
    return out


def _leaves(table: dict, schema: dict, prefix: str = "") -> dict:
    """``{"aiding.nhc": True, ...}``: the keys a (partial) job table sets, dotted."""
    out = {}
    for key, value in table.items():
        spec = schema.get(key)
        if spec is not None and _is_table_spec(spec) and isinstance(value, dict):
            out.update(_leaves(value, spec, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def platform_profile(name: str) -> dict:
    """The job tables of the platform profile ``name``, checked against the schema (an unknown
    key or a wrong type names the profiles file and the key)."""
    return _validate(profile(name), SCHEMA, "", str(profiles_path()), set(), defaults=False)


@dataclass
class Job:
    """A validated job: the settings (dict of tables with the defaults of the platform profile
    and of the schema filled in: what runs), the file it came from, any simulation tables it
    carries and the keys the file gave explicitly (``given``).

    ``platform`` is the profile (``[job] platform``); ``from_profile`` the profile's values the
    job did not override (``{dotted key: value}``); :attr:`explicit` the job file's own values.
    """

    settings: dict
    path: Path | None = None
    simulation: dict = field(default_factory=dict)
    given: frozenset = frozenset()
    platform: str = DEFAULT_PLATFORM
    from_profile: dict = field(default_factory=dict)

    @property
    def explicit(self) -> dict:
        """The job file's own values, ``{dotted key: value}``."""
        return {k: _get(self.settings, k) for k in sorted(self.given)}

    def __getitem__(self, table: str) -> dict:
        return self.settings[table]

    @property
    def base_dir(self) -> Path:
        return self.path.parent if self.path is not None else Path.cwd()

    @property
    def simulated(self) -> bool:
        """The job simulates its data (simulation tables, no inputs.imu.path)."""
        return bool(self.simulation) and self.settings["inputs"]["imu"]["path"] is None

    def resolve(self, p: str | None) -> Path | None:
        """Path relative to the job file (absolute paths unchanged)."""
        if p is None:
            return None
        q = Path(p).expanduser()
        return q if q.is_absolute() else (self.base_dir / q).resolve()

    @property
    def output_dir(self) -> Path:
        return self.resolve(self.settings["outputs"]["dir"])

    def input_paths(self) -> list[Path]:
        """Every file the job reads, the job file included (outputs must never overwrite,
        move or delete one)."""
        out = [] if self.path is None else [self.path]
        if self.simulated:
            return out
        for spec in self.settings["inputs"].values():
            for k in ("path", "tag"):
                if spec.get(k):
                    out.append(self.resolve(spec[k]))
        return out

    def to_dict(self) -> dict:
        """The job as a dict that loads to the same job: the keys given explicitly or changed
        from their default in memory, plus the simulation tables (for work units)."""
        out: dict = {k: v for k, v in self.simulation.items()}
        for key, spec in iter_schema():
            v = _get(self.settings, key)
            if key in self.given or v != spec["default"]:
                d = out
                parts = key.split(".")
                for p in parts[:-1]:
                    d = d.setdefault(p, {})
                d[parts[-1]] = v
        return out


def load_job_dict(data: dict, path: str | Path | None = None, *, complete: bool = True) -> Job:
    """Validate a job given as a dict (as parsed from TOML) and resolve it: schema defaults,
    overlaid by the platform profile (``[job] platform``), overlaid by the job's own keys.

    ``complete=False`` checks names, types and values only (shared base settings that jobs
    complete, e.g. ``insgnss batch --settings``), not whether the run reads every key.
    """
    file = None if path is None else str(path)
    if not isinstance(data, dict):
        raise ConfigError("a job must be a TOML table", file=file)
    sim = {k: v for k, v in data.items() if k in SIMULATION_TABLES}
    rest = {k: v for k, v in data.items() if k not in SIMULATION_TABLES}
    given: set = set()
    own = _validate(rest, SCHEMA, "", file, given, defaults=False)  # the job's keys, checked
    # resolution: schema default < platform profile < the job's own keys
    platform = own.get("job", {}).get("platform", DEFAULT_PLATFORM)
    prof = platform_profile(platform)
    settings = _validate(_overlay(prof, own, SCHEMA), SCHEMA, "", file, set())
    from_profile = {k: v for k, v in _leaves(prof, SCHEMA).items() if k not in given}
    job = Job(settings=settings, path=None if path is None else Path(path).resolve(),
              simulation=sim, given=frozenset(given), platform=platform,
              from_profile=from_profile)
    if complete:
        _check_use(settings, given, sim, file)
        rate = sim.get("scenario", {}).get("imu_rate") if isinstance(sim.get("scenario"),
                                                                     dict) else None
        if job.simulated and _is_number(rate) and math.isfinite(rate) and rate > 0:
            check_job_against_data(job, 1.0 / float(rate))
    return job


def check_job_against_data(job: Job, imu_interval: float,
                           imu_span: tuple[float, float] | None = None) -> None:
    """The checks that need the data: intervals of at least one IMU interval
    (``min_imu_intervals`` of the schema: outage lengths and gaps, ``filter.epoch_interval``,
    ``aiding.nhc_interval``, the static window) and ``initialization.start_time`` inside
    ``imu_span``. Keys the run does not read are skipped. Raises ConfigError naming the key.
    """
    dt = float(imu_interval)
    file = None if job.path is None else str(job.path)
    sim = job.simulation if job.simulated else None
    if math.isfinite(dt) and dt > 0:
        for key, spec in iter_schema():
            m = spec["min_imu_intervals"]
            v = _get(job.settings, key)
            if not m or v is None or not all(c.test(job.settings, sim) for c in spec["when"]):
                continue
            for i, x in enumerate([b - a for a, b in v] if isinstance(v, list) else [v]):
                if x < m * dt * (1.0 - 1e-9):
                    raise ConfigError(
                        f"shorter than {'one IMU interval' if m == 1 else f'{m} IMU intervals'}",
                        file=file, column=key,
                        expected=f">= {m * dt:.6g} s ({m} x the IMU interval {dt:.6g} s)",
                        found=f"{x:.6g} s" + (f" (window {i + 1})" if isinstance(v, list)
                                              else ""))
    start = job.settings["initialization"]["start_time"]
    if imu_span is not None and start is not None and \
            not float(imu_span[0]) <= start < float(imu_span[1]):
        raise ConfigError("start time outside the IMU data", file=file,
                          column="initialization.start_time",
                          expected=f"{imu_span[0]!r} <= start_time < {imu_span[1]!r}",
                          found=repr(start))


def load_job(path: str | Path) -> Job:
    """Read and validate a TOML job file."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError("job file not found", file=path) from None
    except IsADirectoryError:
        raise ConfigError("the job is a folder, not a TOML file", file=path) from None
    except UnicodeDecodeError as exc:
        raise ConfigError("job file is not UTF-8 text", file=path, found=str(exc)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read the job file ({exc.strerror or exc})",
                          file=path) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        row = None
        if "(at line " in msg:
            try:
                row = int(msg.split("(at line ")[1].split(",")[0])
            except ValueError:
                row = None
        raise ConfigError(f"not valid TOML: {msg}", file=path, row=row) from None
    return load_job_dict(data, path)


def schema_markdown() -> str:
    """The schema as Markdown tables (docs/jobs.md, section "Schema", is this text)."""
    lines = []

    def walk(schema, prefix):
        rows = []
        for key, spec in schema.items():
            if _is_table_spec(spec):
                walk(spec, f"{prefix}{key}.")
                continue
            choices = ", ".join(map(str, spec["choices"] or ()))
            valid = (f"{'any' if spec['type'] is list else 'one'} of {choices}"
                     if spec["choices"] else spec["check"].doc if spec["check"] else "")
            when = "; ".join(c.doc for c in spec["when"] if c is not STANDARD
                             and c is not RECORDED and c.doc != f"{prefix}path is given")
            meaning = spec["doc"] + (f". Read only when {when}" if when else "")
            if spec["min_imu_intervals"]:
                valid += f"; at least {spec['min_imu_intervals']} IMU interval(s)"
            rows.append(f"| `{prefix}{key}` | {_type_name(spec['type'])} | "
                        f"`{spec['default']!r}` | {valid} | {meaning} |")
        if rows:
            lines.append(f"\n### `[{prefix.rstrip('.') or 'top level'}]`\n")
            lines.append("| key | type | default | valid values | meaning |")
            lines.append("|---|---|---|---|---|")
            lines.extend(rows)

    walk(SCHEMA, "")
    return "\n".join(lines) + "\n"


_finish_schema()
