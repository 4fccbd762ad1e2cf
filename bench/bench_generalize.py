"""Cross-dataset protocol (docs/generalization.md): one configuration per platform,
every method decision made on one group of recordings and reported on another.

Groups
------
``decide``  recordings the decisions were made on (simulation with known noise, the car drive):
            the platform profiles' physics, the static-window rule, the velocity-lag estimate and
            the self-tuning's design (one-step then coast view, their weighting) were chosen here;
``report``  recordings that took no part in any decision (the hand-held walk): their numbers
            are what a user gets on data insgnss was not tuned on.

The bench FAILS (exit status 1) when a job carries a tuned noise value
(:func:`insgnss.profiles.tuned_noise_keys`: any ``*_std``, ``*_psd``, ``sigma_*``, noise scale,
``q_scale``, ``gnss_min_std`` or ``[filter.imu_model]`` number in the job file): profiles and
self-tuning are the only allowed sources. It prints one table.

Adding a recording is one :class:`Row` in :data:`ROWS` (a job file, its group and a scorer);
the foot-mounted rows (PyShoe folds, x-io, UCR) are meant to be added the same way.

Run: ``python bench/bench_generalize.py [--only NAME ...] [--no-check]``. Timing printed per row
(the numbers are not timed tests; the machine may be shared).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import tomllib
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SCORER = SHARED / "eval" / "drive_outage.py"


@dataclass
class Row:
    """One recording of the protocol.

    ``run()`` returns ``{metric: value}``; ``job`` (if any) is checked for tuned noise values;
    ``targets`` are ``{metric: (op, bound)}`` printed next to the values (``"<="`` or ``">="``).
    """

    name: str
    group: str  # "decide" or "report"
    platform: str
    run: Callable[[], dict]
    job: Path | None = None
    targets: dict = field(default_factory=dict)
    needs: tuple = ()  # shared data folders the row reads


def _score(path: Path, ref: Path) -> dict:
    r = subprocess.run([sys.executable, str(SCORER), str(path), "--ref", str(ref), "--json"],
                       capture_output=True, text=True, check=True)
    return json.loads(r.stdout)


def outage_job_row(name: str, group: str, job_file: Path, ref: Path, targets: dict,
                   needs: tuple, overrides: dict | None = None) -> Row:
    """A real recording with the data author's outage rule, scored by the shared scorer;
    ``overrides`` (``{"table.key": value}``) shows a variant of its configuration."""

    def run() -> dict:
        from insgnss.config import load_job
        from insgnss.pipeline import run_job, write_outputs

        job = load_job(job_file)
        for key, value in (overrides or {}).items():
            table, k = key.split(".")
            job.settings[table][k] = value
        job.settings["outputs"]["formats"] = ["csv", "eval"]
        job.settings["outputs"]["report"] = False
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = run_job(job, progress=False)
        out = Path(tempfile.mkdtemp(prefix=f"insgnss_{name}_"))
        paths = write_outputs(res, out)
        fwd = _score(paths["forward_eval.csv"], ref)
        smo = _score(paths["smoothed_eval.csv"], ref)
        at = res.summary.get("autotune")
        return {"fwd_end_mean_m": fwd["outage_summary"]["end_h_err_m"]["mean"],
                "smo_in_rms_mean_m": smo["outage_summary"]["rms_h_err_m"]["mean"],
                "fwd_non_outage_m": fwd["non_outage"]["rms_h_err_m"],
                "smo_non_outage_m": smo["non_outage"]["rms_h_err_m"],
                "autotune_evals": at["evaluations"] if at else 0}

    return Row(name, group, load_platform(job_file), run, job_file, targets, needs)


def load_platform(job_file: Path) -> str:
    return tomllib.loads(job_file.read_text()).get("job", {}).get("platform", "generic")


def simulation_row() -> Row:
    """The self-tuning on a simulation with known white noise (tests/test_autotune.py): errors of
    the recovered ARW, VRW and GNSS sigma scale, and the forward NEES of the fixed and the
    tuned model (2 for a consistent filter)."""

    def run() -> dict:
        import numpy as np

        sys.path.insert(0, str(REPO / "tests"))
        import test_autotune as ta

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fixed, tuned = ta._run(False), ta._run(True)
        p = tuned.summary["autotune"]["parameters"]
        truth = {"gyro_arw": np.radians(ta.TRUE_ARW) / 60, "accel_vrw": ta.TRUE_VRW / 60,
                 "gnss_pos_scale_q5": ta.TRUE_SCALE}
        out = {f"{k}_err_pct": 100 * (p[k]["value"] / v - 1) for k, v in truth.items()}
        out["nees_fixed"] = ta._coverage(fixed)[1]
        out["nees_tuned"] = ta._coverage(tuned)[1]
        return out

    return Row("sim_autotune", "decide", "generic", run,
               targets={"gyro_arw_err_pct": ("abs<=", 20), "accel_vrw_err_pct": ("abs<=", 20),
                        "gnss_pos_scale_q5_err_pct": ("abs<=", 20)})


DATA = SHARED / "data" / "gnss-imu-rtklibexplorer"

#: the protocol: decide on the simulation and the drive, report on the walk
ROWS: list[Row] = [
    simulation_row(),
    outage_job_row("drive_0708", "decide", REPO / "scenarios" / "drive_0708.toml",
                   DATA / "drive_0708" / "gnss_1934_sf.pos",
                   {"fwd_end_mean_m": ("<=", 1.8), "smo_in_rms_mean_m": ("<=", 0.11),
                    "fwd_non_outage_m": ("<=", 0.02)},
                   ("gnss-imu-rtklibexplorer/drive_0708",)),
    # the same job with the profile's prior model (no self-tuning): what the self-tuning changes
    outage_job_row("drive_prior", "decide", REPO / "scenarios" / "drive_0708.toml",
                   DATA / "drive_0708" / "gnss_1934_sf.pos", {},
                   ("gnss-imu-rtklibexplorer/drive_0708",), {"filter.autotune": False}),
    outage_job_row("walk_0827", "report", REPO / "scenarios" / "walk_0827.toml",
                   DATA / "walk_0827" / "gnss_1730_sf.pos",
                   {"fwd_end_mean_m": ("<=", 4.0), "smo_in_rms_mean_m": ("<=", 0.20),
                    "fwd_non_outage_m": ("<=", 0.05)},
                   ("gnss-imu-rtklibexplorer/walk_0827",)),
]


def check_jobs(rows) -> list[str]:
    """Tuned noise values carried by the rows' job files (one message per key)."""
    from insgnss.config import SIMULATION_TABLES
    from insgnss.profiles import tuned_noise_keys

    bad = []
    for r in rows:
        if r.job is None:
            continue
        data = tomllib.loads(r.job.read_text())
        data = {k: v for k, v in data.items() if k not in SIMULATION_TABLES}
        for key, value in tuned_noise_keys(data).items():
            bad.append(f"{r.job.relative_to(REPO)}: {key} = {value!r} is a tuned noise value "
                       "(profiles and filter.autotune are the allowed sources)")
    return bad


def _meets(value, target) -> str:
    op, bound = target
    ok = {"<=": value <= bound, ">=": value >= bound, "abs<=": abs(value) <= bound}[op]
    return f"{'ok' if ok else 'MISS'} ({op.replace('abs', '|x|')} {bound:g})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", nargs="*", help="run only these rows")
    ap.add_argument("--no-check", action="store_true", help="skip the tuned-value check")
    args = ap.parse_args()
    rows = [r for r in ROWS if not args.only or r.name in args.only]
    bad = [] if args.no_check else check_jobs(ROWS)
    lines = []
    for r in rows:
        missing = [n for n in r.needs if not (SHARED / "data" / n).exists()]
        if missing:
            lines.append((r, None, f"skipped: {', '.join(missing)} absent", 0.0))
            continue
        t0 = time.perf_counter()
        metrics = r.run()
        lines.append((r, metrics, "", time.perf_counter() - t0))
    print(f"{'row':14s} {'group':7s} {'platform':11s} {'metric':26s} {'value':>10s}  target")
    for r, metrics, note, dt in lines:
        if metrics is None:
            print(f"{r.name:14s} {r.group:7s} {r.platform:11s} {note}")
            continue
        for k, v in metrics.items():
            tgt = _meets(v, r.targets[k]) if k in r.targets else ""
            print(f"{r.name:14s} {r.group:7s} {r.platform:11s} {k:26s} {v:10.4g}  {tgt}")
        print(f"{r.name:14s} {r.group:7s} {r.platform:11s} {'run time [s]':26s} {dt:10.1f}")
    print("\ndecide: the recordings the method decisions were made on; report: recordings that "
          "took no part in them (docs/generalization.md)")
    if bad:
        print("\nFAIL: jobs carry tuned noise values:")
        for b in bad:
            print(f"  {b}")
        return 1
    print("check: no job carries a tuned noise value")
    return 0


if __name__ == "__main__":
    sys.exit(main())
