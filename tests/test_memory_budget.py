"""A run whose memory budget (``[filter] store_memory_mb``) is far below its arrays writes
byte-identical outputs to a run that holds everything in memory: the node store and the
IMU-rate forward and smoothed tables are then memory-mapped (:mod:`insgnss.io.spill`), written
and read in blocks whose pages are given back, and the writers, the evaluation and the summary
read only the rows and columns they use (the smoothed table is formed at those rows only,
unless every sample is written)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from job_helpers import recorded_job_text, simulate_recording

from insgnss.cli import main
from insgnss.io import spill

#: summary keys that differ between any two runs (timings, the job file and its budget)
VOLATILE = ("timing_s", "provenance", "job_resolved", "resolved_job", "created", "version",
            "run_time", "files", "input_files")


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return simulate_recording(tmp_path_factory.mktemp("budget") / "data")


def _run(tmp_path, recording, name: str, budget: float, rate: str) -> dict[str, bytes]:
    text = recorded_job_text(recording, filter=f"store_memory_mb = {budget}\n").replace(
        "[outputs]\n", f'[outputs]\nformats = ["csv", "parquet", "nav", "eval"]\n'
                       f'rate_hz = {rate}\ncolumns = ["all"]\n')
    job = tmp_path / f"{name}.toml"
    job.write_text(text)
    out = tmp_path / name
    assert main(["process", str(job), "-o", str(out), "--no-progress"]) == 0
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.is_file()}


def _summary(raw: bytes) -> dict:
    s = json.loads(raw)
    return {k: v for k, v in s.items() if k not in VOLATILE}


@pytest.mark.parametrize("rate", ['"imu"', '"auto"'])
def test_tiny_budget_gives_byte_identical_outputs(tmp_path, recording, monkeypatch, rate):
    mem = _run(tmp_path, recording, "memory", 1.0e6, rate)
    mapped_bytes = []
    original = spill.SpillAllocator.__call__

    def counting(self, shape, dtype=float):
        a = original(self, shape, dtype)
        if spill.is_mapped(a):
            mapped_bytes.append(a.nbytes)
        return a

    monkeypatch.setattr(spill.SpillAllocator, "__call__", counting)
    monkeypatch.setattr(spill, "BLOCK_BYTES", 50_000)  # many blocks of a few hundred rows
    tiny = _run(tmp_path, recording, "tiny", 1.0, rate)
    n_rows = 9_000  # the recording: about 93 s at 100 Hz, 30 columns of float64
    tables = sum(b >= n_rows * 30 * 8 for b in mapped_bytes)
    # the forward IMU-rate table is mapped; the smoothed one is formed whole (and mapped) only
    # when every sample is written, else read at the rows used (store.AssembledTable)
    assert tables == (2 if rate == '"imu"' else 1)
    assert sorted(mem) == sorted(tiny)
    assert {"forward.csv", "smoothed.parquet", "smoothed.nav", "innovations.csv"} <= set(mem)
    for name in mem:
        if name == "summary.json":
            assert _summary(mem[name]) == _summary(tiny[name])
        else:
            assert mem[name] == tiny[name], name
    s = json.loads(mem["summary.json"])
    assert np.isfinite(s["evaluation"]["smoothed"]["rms_h_m"])
    assert s["evaluation"]["smoothed"]["rms_h_m"] < s["evaluation"]["forward"]["rms_h_m"]
