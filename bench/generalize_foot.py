#!/usr/bin/env python3
"""Foot rows of the cross-dataset generalization protocol: one configuration, data it was
never tuned on.

Protocol
--------
- **PyShoe Vicon, two folds** (``shared/data/pyshoe-vicon``, 28 trials in name order; fold A
  = trials 1, 3, 5, ..., fold B = trials 2, 4, 6, ...). Each design decision of the foot
  profile is a *choice* between configurations (:data:`CHOICES`: the profile, and the
  alternatives it was chosen against). The choice is made on one fold (lowest mean smoothed
  2-D ARMSE of the shared scorer ``shared/eval/pyshoe_armse.py``) and the chosen configuration
  is scored on the other fold, and vice versa; the cross-validated mean is the mean over all
  28 trials of these held-out scores (each trial scored by a configuration chosen without it).
- **x-io loops** (``shared/data/foot-xio-gait``): loop closure, the final horizontal
  displacement from the start as a percentage of the distance walked (stance to stance,
  :func:`insgnss.strides.stance_distance`); the author reports 0.082 m / 0.421 m.
- **UCR** (``shared/data/foot-ucr-zupt``): horizontal RMS against the foot-position truth.
  Frame alignment: the truth frame is z-down (the mirror image of east-north-up), so the
  solution's (north, east) is compared with the truth's (x, y); the rotation and translation
  are a 2-D rigid fit over the **first 10 s** of the track (its first straight leg, about 4 m:
  the equivalent of knowing the initial heading, which ZUPT cannot observe); the fit over the
  whole track is reported beside it. Published (no fit, the authors' frame): EKF-ZUPT 1.484 m
  right / 3.904 m left, factor-graph ZUPT 0.510 / 2.169 m.

x-io and UCR are run with the profile's configuration as it is (nothing chosen on them).

Use from the bench (``bench/bench_generalize.py``)::

    from generalize_foot import foot_rows
    rows = foot_rows()          # list of dicts, see ROW_KEYS

or run it: ``PYTHONPATH=. python bench/generalize_foot.py [--json] [--only pyshoe|xio|ucr]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from foot_data import (  # noqa: E402
    SITES,
    UCR_PUBLISHED,
    UCR_RATE,
    XIO_AUTHOR,
    XIO_WALKS,
    convert,
    fitted_rms,
    read_ucr,
    read_xio,
    ucr_truth,
)
from run_pyshoe import DEFAULT_DATA, score, solution_ned  # noqa: E402

from insgnss.foot import FootConfig, run_foot_ins  # noqa: E402
from insgnss.io.native import atomic_write  # noqa: E402
from insgnss.strides import stance_distance  # noqa: E402

#: keys of every row: dataset, recording (or fold), metric, value, unit, target (None: no
#: target), passed (None: no target), chosen_on (the recordings the configuration was chosen
#: on), configuration, note
ROW_KEYS = ("dataset", "recording", "metric", "value", "unit", "target", "passed", "chosen_on",
            "configuration", "note")

#: the decisions of the foot profile, as the alternatives each was chosen against (FootConfig
#: overrides; {} is the profile itself). docs/generalization.md, foot section.
CHOICES: dict[str, dict] = {
    "foot profile": {},
    "valley window 1.5 strides": {"detector": {"valley_strides": 1.5}},
    "valley window 3 strides": {"detector": {"valley_strides": 3.0}},
    "accel noise 0.01 + 1 % dynamic (before)": {"accel_psd": 0.01, "accel_dyn_noise": 0.01},
    "gait-adaptive detector, no selection (before)": {
        "threshold_selection": "none", "accel_psd": 0.01, "accel_dyn_noise": 0.01,
        "detector": {"method": "adaptive", "adapt_factor": 10.0}},
}
#: UCR start alignment: rigid fit over the first seconds of the track
UCR_FIT_SECONDS = 10.0


def config_for(choice: dict, base: FootConfig | None = None) -> FootConfig:
    """``base`` (default: the foot profile, ``FootConfig()``) with a choice's overrides."""
    d = (base or FootConfig()).to_dict()
    for k, v in choice.items():
        d[k] = {**d[k], **v} if isinstance(v, dict) else v
    return FootConfig.from_dict(d)


def _row(**kw) -> dict:
    row = dict.fromkeys(ROW_KEYS)
    row.update(kw)
    if row["target"] is not None and row["value"] is not None:
        row["passed"] = bool(row["value"] <= row["target"])
    return row


# --- PyShoe: two folds --------------------------------------------------------------------
def folds(trials: list[Path]) -> dict[str, list[str]]:
    """Fold A: the 1st, 3rd, ... trial in name order; fold B: the 2nd, 4th, ..."""
    names = [p.stem for p in sorted(trials)]
    return {"A": names[0::2], "B": names[1::2]}


def pyshoe_scores(config: FootConfig, data: Path = DEFAULT_DATA) -> dict[str, dict]:
    """Smoothed and forward 2-D ARMSE of every trial from the shared scorer:
    ``{trial: {"smoothed": m, "forward": m}}``."""
    out: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        dirs = {"smoothed": Path(tmp) / "s", "forward": Path(tmp) / "f"}
        for d in dirs.values():
            d.mkdir()
        for mat in sorted(data.glob("*.mat")):
            imu, _ = convert.to_insgnss(mat)
            lat, lon, h = SITES["pyshoe"]
            res = run_foot_ins(imu, config, lat=lat, lon=lon, height=h)
            for kind, traj in (("smoothed", res.trajectory), ("forward", res.forward)):
                sol = solution_ned(traj)
                atomic_write(dirs[kind] / f"{mat.stem}.csv",
                             lambda p, s=sol: s.to_csv(p, index=False, float_format="%.6f"))
        for kind, d in dirs.items():
            for name, r in score(data, d).items():
                out.setdefault(name, {})[kind] = r["ours"]
    return out


def pyshoe_rows(choices: dict[str, dict] = CHOICES, data: Path = DEFAULT_DATA,
                target: float = 0.065) -> list[dict]:
    """Choose on one fold, score on the other, and vice versa (module docstring)."""
    trials = sorted(data.glob("*.mat"))
    if not trials:
        return []
    fl = folds(trials)
    scores = {name: pyshoe_scores(config_for(c), data) for name, c in choices.items()}
    rows = []
    held = {"smoothed": [], "forward": []}
    for on, report in (("A", "B"), ("B", "A")):
        mean_on = {name: np.mean([s[t]["smoothed"] for t in fl[on]]) for name, s in scores.items()}
        chosen = min(mean_on, key=mean_on.get)
        for kind in ("smoothed", "forward"):
            vals = [scores[chosen][t][kind] for t in fl[report]]
            held[kind] += vals
            rows.append(_row(dataset="pyshoe", recording=f"fold {report} ({len(vals)} trials)",
                             metric=f"mean 2-D ARMSE, {kind}", value=float(np.mean(vals)),
                             unit="m", chosen_on=f"fold {on}", configuration=chosen,
                             note="choice on fold " + on + ": " + ", ".join(
                                 f"{k} {v:.4f}" for k, v in mean_on.items())))
    for kind in ("smoothed", "forward"):
        rows.append(_row(dataset="pyshoe", recording="28 trials, cross-validated",
                         metric=f"mean 2-D ARMSE, {kind}", value=float(np.mean(held[kind])),
                         unit="m", target=target if kind == "smoothed" else None,
                         chosen_on="the other fold", configuration="per fold (above)"))
    prof = scores[next(iter(choices))]
    rows.append(_row(dataset="pyshoe", recording="28 trials", metric="mean 2-D ARMSE, smoothed",
                     value=float(np.mean([s["smoothed"] for s in prof.values()])), unit="m",
                     chosen_on="both folds", configuration=next(iter(choices)),
                     note="the profile on all trials (PyShoe per-trial truth-tuned SHOE: "
                          "0.056 m)"))
    return rows


# --- x-io loops and UCR --------------------------------------------------------------------
def xio_rows(config: FootConfig | None = None, target_pct: float = 0.5) -> list[dict]:
    """Loop closure of the two x-io walks with the profile configuration."""
    cfg = config or FootConfig()
    rows = []
    for name in XIO_WALKS:
        imu = read_xio(name)
        res = run_foot_ins(imu, cfg, lat=SITES["xio"][0], lon=SITES["xio"][1],
                           height=SITES["xio"][2])
        walked = stance_distance(res.forward[["east", "north"]].to_numpy(),
                                 res.stillness.still.to_numpy(bool))
        for kind, sol in (("smoothed", res.trajectory), ("forward", res.forward)):
            d = float(np.hypot(sol["east"].iloc[-1], sol["north"].iloc[-1]))
            rows.append(_row(dataset="xio", recording=name, metric=f"loop closure, {kind}",
                             value=100.0 * d / walked, unit="% of distance walked",
                             target=target_pct if kind == "smoothed" else None,
                             chosen_on="pyshoe (profile)", configuration="foot profile",
                             note=f"{d:.3f} m of {walked:.1f} m (author {XIO_AUTHOR[name]} m)"))
    return rows


def ucr_rows(config: FootConfig | None = None) -> list[dict]:
    """Horizontal RMS of both UCR feet (start alignment and whole-track fit)."""
    cfg = config or FootConfig()
    rows = []
    fit_n = int(round(UCR_FIT_SECONDS * UCR_RATE))
    for side in ("right", "left"):
        imu = read_ucr(side)
        res = run_foot_ins(imu, cfg, lat=SITES["ucr"][0], lon=SITES["ucr"][1],
                           height=SITES["ucr"][2])
        truth = ucr_truth(side)
        pub = UCR_PUBLISHED["ekf_zupt"][side]
        for kind, sol in (("smoothed", res.trajectory), ("forward", res.forward)):
            n = min(len(sol), len(truth))
            a = sol[["north", "east"]].to_numpy()[:n]  # the truth is the NED mirror of ENU
            b = truth[:n, :2]
            start = fitted_rms(a, b, slice(0, fit_n))
            whole = fitted_rms(a, b)
            rows.append(_row(dataset="ucr", recording=f"{side} foot",
                             metric=f"horizontal RMS, {kind}, fit over the first "
                                    f"{UCR_FIT_SECONDS:.0f} s", value=start, unit="m",
                             target=pub, chosen_on="pyshoe (profile)",
                             configuration="foot profile",
                             note=f"whole-track fit {whole:.3f} m; published EKF-ZUPT {pub} m, "
                                  f"FGO-ZUPT {UCR_PUBLISHED['fgo_zupt'][side]} m (no fit)"))
    return rows


def foot_rows(only: str | None = None) -> list[dict]:
    """All foot rows of the cross-dataset table (``only``: one of pyshoe, xio, ucr)."""
    parts = {"pyshoe": pyshoe_rows, "xio": xio_rows, "ucr": ucr_rows}
    return [r for k, fn in parts.items() if only in (None, k) for r in fn()]


def print_rows(rows: list[dict]) -> None:
    print(f"{'dataset':7s} {'recording':28s} {'metric':44s} {'value':>8s} {'target':>7s} "
          f"{'ok':>4s}  chosen on / configuration")
    for r in rows:
        tgt = "" if r["target"] is None else f"{r['target']:.3f}"
        ok = "" if r["passed"] is None else ("yes" if r["passed"] else "NO")
        print(f"{r['dataset']:7s} {r['recording']:28s} {r['metric']:44s} {r['value']:8.4f} "
              f"{tgt:>7s} {ok:>4s}  {r['chosen_on']} / {r['configuration']}")
        if r["note"]:
            print(f"{'':8s}{r['note']}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", action="store_true")
    p.add_argument("--only", choices=["pyshoe", "xio", "ucr"], default=None)
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    rows = foot_rows(a.only)
    if a.json:
        print(json.dumps(rows, indent=1))
    else:
        print_rows(rows)
        print(f"({time.perf_counter() - t0:.0f} s)")
    failed = [r for r in rows if r["passed"] is False]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
