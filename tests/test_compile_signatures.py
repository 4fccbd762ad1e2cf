"""One compiled specialisation per kernel and job: a second one (a literal argument, another
layout, an optional argument given or omitted) costs its whole numba compile again on a cold
cache. Checked in a fresh interpreter with an empty numba cache (callees loaded from a cache
would not be listed) and without LLVM optimisation (the count does not depend on it, the
compile time does), so that every kernel this run needs is compiled and counted; the
ahead-of-time kernels are off (``INSGNSS_AOT=0``: this is the JIT path's count)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys
sys.path.insert(0, {tests!r})
import numpy as np
from filter_sim import car_truth, corrupt_imu, gnss_from_truth, perturbed_initial
from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity, run_filter
from insgnss.filter import kalman, smoother
from insgnss.imu import grade
from insgnss.mechanization import strapdown
from insgnss.mechanization.strapdown import mechanize

truth = car_truth(60.0, 50.0)
model = grade("tactical")
rng = np.random.default_rng(3)
imu, _ = corrupt_imu(truth, model, rng)
gnss = gnss_from_truth(truth, rng)
init, _ = perturbed_initial(truth, rng)
mechanize(imu, init)  # the free mechanization: the step with a run-time height flag
cfg = FilterConfig(imu_model=model, scale_factors=True)  # 21 states
res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
assert res.smoothed is not None
kernels = {{"strapdown_step": strapdown.strapdown_step, "mbf_backward": smoother.mbf_backward,
           "mbf_backward15": getattr(smoother, "_mbf_backward15", None),
           "through_update": smoother._through_update,
           "back_through_sparse": smoother._back_through_sparse,
           "kalman_predict": kalman._predict, "kalman_update": kalman._update}}
print(json.dumps({{k: [str(s) for s in f.signatures] if f is not None else []
                  for k, f in kernels.items()}}))
"""


def test_one_specialisation_per_kernel_in_a_filter_run(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(tmp_path),
           "NUMBA_OPT": "0", "INSGNSS_AOT": "0"}
    out = subprocess.run([sys.executable, "-c", CHILD.format(tests=str(ROOT / "tests"))],
                         capture_output=True, text=True, env=env, cwd=ROOT, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    sigs = json.loads(out.stdout.strip().splitlines()[-1])
    # the filter's interval step and the free mechanization share one compiled step
    assert len(sigs["strapdown_step"]) == 1, sigs["strapdown_step"]
    assert "Literal" not in sigs["strapdown_step"][0]
    # a 21-state smoother compiles the general pass once and not the 15-state entry point
    assert len(sigs["mbf_backward"]) == 1, sigs["mbf_backward"]
    assert sigs["mbf_backward15"] == []
    assert len(sigs["through_update"]) == 1, sigs["through_update"]
    # the general epochs' predict/update: one specialisation whatever the stacked row count
    assert len(sigs["kalman_predict"]) == 1, sigs["kalman_predict"]
    assert len(sigs["kalman_update"]) == 1, sigs["kalman_update"]
    assert len(sigs["back_through_sparse"]) == 1, sigs["back_through_sparse"]


VECTOR_CHILD = r"""
import json
import numpy as np
import pandas as pd
from insgnss import earth

lat = np.radians(np.linspace(-80.0, 80.0, 7))
lon = np.radians(np.linspace(-170.0, 170.0, 7))
h = np.linspace(-50.0, 3000.0, 7)
table = pd.DataFrame({"lat": lat, "lon": lon, "h": h})
ro = table["lat"].to_numpy(), table["lon"].to_numpy(), table["h"].to_numpy()
for a in ro:
    a.flags.writeable = False  # what a copy-on-write pandas column gives
block = np.column_stack([lat, lon, h])  # column slices: layout 'A'
calls = [(lat, lon, h), ro, (block[:, 0], block[:, 1], block[:, 2]), (lat[3], lon[3], h[3]),
         (lat, lon[2], 0.0), (lat.reshape(7, 1), lon.reshape(1, 7), h[0])]
ecef = [earth.geodetic_to_ecef(*c) for c in calls]
disp = [earth.enu_displacement_to_geodetic(c[0], c[2], 1.0, 2.0, c[1]) for c in calls]
N = earth.A / np.sqrt(1.0 - earth.E2 * np.sin(lat) ** 2)
want = ((N + h) * np.cos(lat) * np.cos(lon), (N + h) * np.cos(lat) * np.sin(lon),
        (N * (1.0 - earth.E2) + h) * np.sin(lat))
print(json.dumps({
    "ecef_sigs": [str(s) for s in earth.geodetic_to_ecef_nb.signatures],
    "disp_sigs": [str(s) for s in earth._enu_displacement_to_geodetic.signatures],
    "same": all(np.array_equal(ecef[0][i], ecef[k][i]) for k in (1, 2) for i in range(3)),
    "scalar": [type(x).__name__ for x in ecef[3]] + [float(ecef[3][0] - ecef[0][0][3])],
    "shapes": [list(np.shape(ecef[5][0])), list(np.shape(disp[5][1])), list(np.shape(disp[4][2]))],
    "max_diff": float(max(np.max(np.abs(ecef[0][i] - want[i])) for i in range(3))),
}))
"""


def test_vectorised_earth_functions_compile_once(tmp_path):
    """``geodetic_to_ecef`` / ``enu_displacement_to_geodetic`` compile one specialisation
    whatever their callers pass (read-only pandas columns, column slices, scalars,
    broadcasting shapes), with unchanged values."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(tmp_path),
           "NUMBA_OPT": "0", "INSGNSS_AOT": "0"}
    out = subprocess.run([sys.executable, "-c", VECTOR_CHILD], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    arr = "Array(float64, 1, 'C', False, aligned=True)"
    assert r["ecef_sigs"] == [f"({arr}, {arr}, {arr})"]
    assert len(r["disp_sigs"]) == 1 and r["disp_sigs"][0].count("'C', False") == 5
    assert r["same"]
    assert r["scalar"][:3] == ["float", "float", "float"] and r["scalar"][3] == 0.0
    assert r["shapes"] == [[7, 7], [7, 7], [7]]
    assert r["max_diff"] < 1e-6  # metres, against the closed form in numpy
