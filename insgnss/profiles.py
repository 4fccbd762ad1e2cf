"""Platform profiles: the job defaults that depend on what carries the IMU.

``[job] platform = "car" | "pedestrian" | "foot" | "aircraft" | "generic"`` selects one row of
``insgnss/data/profiles.toml``: a set of job keys (non-holonomic constraint and its interval,
ZUPT/ZARU and their speed gate, initialization method, heading source and minimum speeds, use
of GNSS velocity, the IMU-GNSS time-offset estimate, the stillness limits of the static window,
the process preset). The job file overrides single keys; keys neither sets take the schema
default (:mod:`insgnss.config`, which validates the profiles against its schema and resolves a
job: schema default < profile < job file).

The values are data, not branches: a new platform is a new table in the TOML file. Each one is
chosen from the physics of the platform (docs/generalization.md), the sigmas of the platform's
own constraints included (how far a car's wheels slip sideways: ``aiding.nhc_std``; how well a
hand-held device points along the path: ``course_heading_std_deg``). The sensor's noise (IMU,
GNSS) never comes from a platform: from the IMU grade, the still periods found in the data or
the maximum likelihood self-tuning (:mod:`insgnss.autotune`).

Which job keys count as *tuned noise values* (:func:`tuned_noise_keys`) is defined here too,
because it is the complement of what profiles and self-tuning provide: a job that carries one
is not using the same configuration as every other recording of its platform
(``bench/bench_generalize.py`` fails on it).
"""

from __future__ import annotations

import re
import tomllib
from functools import lru_cache
from importlib import resources
from pathlib import Path

#: the profiles file shipped with the package
PROFILES_FILE = "profiles.toml"
#: profile used when a job names none (no platform assumption)
DEFAULT_PLATFORM = "generic"


def profiles_path() -> Path:
    """Path of the shipped profiles file (for messages)."""
    return Path(str(resources.files("insgnss") / "data" / PROFILES_FILE))


@lru_cache(maxsize=1)
def _load() -> dict:
    return tomllib.loads(profiles_path().read_text())


def platforms() -> tuple[str, ...]:
    """Names of the platform profiles, in file order."""
    return tuple(_load())


def profile(name: str) -> dict:
    """The job tables a profile sets (a fresh copy; without its ``description``)."""
    import copy

    table = _load()[name]
    return copy.deepcopy({k: v for k, v in table.items() if k != "description"})


def description(name: str) -> str:
    """One-sentence description of a profile."""
    return str(_load()[name].get("description", ""))


# --- tuned noise values ----------------------------------------------------------------------
#: last component of a job key that holds a noise value (a sigma, a density, a noise scale)
_NOISE_NAME = re.compile(r"(^sigma_|_std$|_std_deg$|_psd$|noise|_rw$|std_scale$|^q_scale$|"
                         r"_arw|_vrw|_instability|^gnss_min_std$)")
#: job tables every numeric key of which is a noise value (the IMU error model)
_NOISE_TABLES = ("filter.imu_model.",)


def _numeric(v) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return True
    if isinstance(v, (list, tuple)):
        return bool(v) and all(_numeric(x) for x in v)
    if isinstance(v, dict):
        return bool(v) and all(_numeric(x) for x in v.values())
    return False


def is_tuned_noise_key(key: str, value) -> bool:
    """Whether a job key set to ``value`` is a tuned noise value.

    Definition (docs/generalization.md): a *numeric* value (number, array or table of numbers;
    switches and names never count) whose key

    - lies in ``[filter.imu_model]`` (datasheet noise and bias numbers), or
    - has a last component that is a sigma or a noise density or scale: it starts with
      ``sigma_``, ends with ``_std``, ``_std_deg``, ``_psd``, ``_rw`` or ``std_scale``, is
      ``q_scale`` or ``gnss_min_std``, or contains ``noise``, ``_arw``, ``_vrw`` or
      ``_instability``

    (``aiding.nhc_std``, ``aiding.gnss_min_std``, ``aiding.q_scale``, ``aiding.zupt_std``,
    ``initialization.position_std``, ``foot.sigma_zupt``, ``foot.accel_psd``,
    ``foot.gyro_bias_rw``, ``aiding.detector.sigma_a``, ...). The allowed sources of such
    values are the IMU grade (``filter.imu_grade``), the platform profile and the self-tuning
    (``filter.autotune``).
    """
    if not _numeric(value):
        return False
    if any(key.startswith(t) for t in _NOISE_TABLES):
        return True
    return bool(_NOISE_NAME.search(key.rsplit(".", 1)[-1]))


def _leaves(table: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and not _NOISE_NAME.search(k) and k not in ("columns",):
            out.update(_leaves(v, key + "."))
        else:
            out[key] = v
    return out


def tuned_noise_keys(data: dict) -> dict:
    """The tuned noise values a job (as parsed from its TOML file, before defaults) carries:
    ``{dotted key: value}`` (:func:`is_tuned_noise_key`)."""
    return {k: v for k, v in _leaves(data).items() if is_tuned_noise_key(k, v)}


def markdown() -> str:
    """The profiles as a Markdown table per platform (docs/generalization.md keeps it)."""
    lines = []
    for name in platforms():
        lines.append(f"\n### `{name}`\n")
        lines.append(description(name) + "\n")
        keys = _leaves(profile(name))
        if not keys:
            lines.append("(no key: the schema defaults)")
            continue
        lines.append("| key | value |")
        lines.append("|---|---|")
        lines.extend(f"| `{k}` | `{v!r}` |" for k, v in keys.items())
    return "\n".join(lines) + "\n"


__all__ = ["DEFAULT_PLATFORM", "description", "is_tuned_noise_key", "markdown", "platforms",
           "profile", "profiles_path", "tuned_noise_keys"]
