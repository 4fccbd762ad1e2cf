"""summary.json says what reproduces a run - the insgnss version, the fully resolved job
(defaults filled in) and the SHA-256 of every input file - and the report shows them."""

from __future__ import annotations

import hashlib
import json

from example_data import generate_for

import insgnss
from insgnss.cli import main

JOB = """
[inputs.imu]
format = "native"
path = "imu.csv"

[inputs.gnss]
format = "native"
path = "gnss.csv"

[initialization]
static_duration = 20.0

[outputs]
progress = false
"""


def test_summary_and_report_carry_version_resolved_job_and_checksums(tmp_path):
    generate_for({"inputs": {"imu": {"format": "native", "path": "imu.csv"},
                             "gnss": {"format": "native", "path": "gnss.csv"}}}, tmp_path)
    (tmp_path / "job.toml").write_text(JOB)
    assert main(["process", str(tmp_path / "job.toml"), "-o", str(tmp_path / "out"),
                 "--no-progress"]) == 0
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["version"] == insgnss.__version__
    r = s["job_resolved"]
    # defaults filled in: keys the job file never names
    assert r["filter"]["gate_probability"] == 0.9999 and r["aiding"]["zupt_std"] == 0.02
    assert r["initialization"]["static_duration"] == 20.0
    files = {f["path"].rsplit("/", 1)[1]: f for f in s["input_files"]}
    assert set(files) == {"job.toml", "imu.csv", "gnss.csv"}
    for name, f in files.items():
        data = (tmp_path / name).read_bytes()
        assert f["sha256"] == hashlib.sha256(data).hexdigest() and f["bytes"] == len(data)
    html = (tmp_path / "out" / "report.html").read_text()
    assert insgnss.__version__ in html and "Input files" in html
    assert all(f["sha256"] in html for f in files.values())
    assert "gate_probability" in html  # the resolved job
    inter = (tmp_path / "out" / "report_interactive.html").read_text()
    assert files["imu.csv"]["sha256"] in inter


def test_checksums_beside_the_run_are_those_of_the_files(tmp_path):
    """The input checksums computed in a thread during the run (``checksums_beside``) are the
    files' SHA-256; a thread that could not read a file (None) makes ``provenance`` read again."""
    from types import SimpleNamespace

    from insgnss.job.summary import checksums_beside, input_checksums, provenance

    paths = []
    for k, size in enumerate((0, 10, 3_000_001)):
        p = tmp_path / f"f{k}.bin"
        p.write_bytes(bytes(range(256)) * (size // 256) + b"x" * (size % 256))
        paths.append(p)
    job = SimpleNamespace(input_paths=lambda: paths + [tmp_path / "absent.csv"], settings={},
                          simulation=None)
    got = checksums_beside(job)()
    assert got == input_checksums(job)
    assert [f["sha256"] for f in got] == [hashlib.sha256(p.read_bytes()).hexdigest()
                                          for p in paths]
    assert provenance(job, lambda: None)["input_files"] == got
