"""One compiled specialisation per kernel and job: a second one (a literal argument, another
layout, an optional argument given or omitted) costs its whole numba compile again on a cold
cache. Checked in a fresh interpreter with an empty numba cache (callees loaded from a cache
would not be listed) and without LLVM optimisation (the count does not depend on it, the
compile time does), so that every kernel this run needs is compiled and counted."""

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
from insgnss.filter import smoother
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
           "back_through_sparse": smoother._back_through_sparse}}
print(json.dumps({{k: [str(s) for s in f.signatures] if f is not None else []
                  for k, f in kernels.items()}}))
"""


def test_one_specialisation_per_kernel_in_a_filter_run(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(tmp_path),
           "NUMBA_OPT": "0"}
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
    assert len(sigs["back_through_sparse"]) == 1, sigs["back_through_sparse"]
