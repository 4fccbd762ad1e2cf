"""Messages that name the actual cause (issue 12, item 7)."""

from __future__ import annotations

import warnings

import pytest
from job_helpers import recorded_job_text, simulate_recording

from insgnss.cli import main
from insgnss.errors import InsgnssError, TimeOrderError
from insgnss.io.tracks import read_trajectory_csv
from insgnss.preprocess import estimate_time_offset


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return simulate_recording(tmp_path_factory.mktemp("rec") / "data")


def test_gnss_a_day_late_with_time_offset_estimation_names_the_missing_overlap(
        recording, tmp_path, capsys):
    """Said "too little turning motion"; the cause is that IMU and GNSS do not overlap."""
    job = tmp_path / "job.toml"
    text = recorded_job_text(recording).replace(
        'path = "' + str(recording) + '/gnss.csv"',
        'path = "' + str(recording) + '/gnss.csv"\ntime_offset = 86400.0')
    text = text.replace("[inputs.imu]\n", "[inputs.imu]\nestimate_time_offset = true\n")
    job.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["process", str(job), "-o", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "turning" not in err and "Traceback" not in err
    assert "no overlap in time" in err
    assert "imu.csv" in err and "gnss.csv" in err
    assert "86400" in err  # the GNSS span, from 86400 s
    assert "IMU from 0" in err
    import multiprocessing

    import insgnss.report as rep

    # the report's figure server, forked before the run, ended with the failed run
    assert rep._SERVER is None and not multiprocessing.active_children()


def test_no_overlap_is_the_same_message_without_estimation(recording):
    from insgnss.validate import check_gnss_in_imu_span

    imu = read_trajectory_csv(recording / "imu.csv", required=())
    gnss = read_trajectory_csv(recording / "gnss.csv")
    late = gnss.set_axis(gnss.index + 86400.0, axis=0)
    late.attrs = dict(gnss.attrs)
    with pytest.raises(TimeOrderError, match="no overlap in time") as exc:
        check_gnss_in_imu_span(late, imu)
    assert "IMU from" in str(exc.value) and "GNSS from" in str(exc.value)


def test_time_offset_estimation_names_too_few_moving_epochs(recording):
    imu = read_trajectory_csv(recording / "imu.csv", required=())
    gnss = read_trajectory_csv(recording / "gnss.csv")
    with pytest.raises(InsgnssError) as exc:
        estimate_time_offset(imu, gnss.loc[:25.0])  # the static start only
    assert "moving" in str(exc.value) and "turning" not in str(exc.value)


def _static_car(explicit: bool):
    """The bundled highway scenario cut to its 100 s parked start: no motion to estimate from."""
    import tomllib
    from pathlib import Path

    from insgnss.config import load_job_dict

    path = Path(__file__).resolve().parents[1] / "scenarios" / "car_highway_tactical_outages.toml"
    data = tomllib.loads(path.read_text())
    data["scenario"]["duration"] = 100.0
    data.setdefault("filter", {})["autotune"] = False  # the time tags, not the noise model
    if explicit:
        data.setdefault("inputs", {}).setdefault("imu", {})["estimate_time_offset"] = True
    return load_job_dict(data, path)


def test_profile_time_offset_without_motion_warns_and_keeps_the_tags():
    """A car profile's default estimate on a parked-only log: warned, offset 0, run completes;
    the same estimate asked for by the job itself stops with the reason."""
    from insgnss.errors import InsgnssWarning, InvalidValueError
    from insgnss.job.run import run_job

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = run_job(_static_car(False), progress=False)
    msgs = [str(w.message) for w in caught if issubclass(w.category, InsgnssWarning)]
    assert any("time-offset estimate is skipped" in m and "moving" in m for m in msgs), msgs
    assert res.summary["complete"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(InvalidValueError, match="moving GNSS epochs"):
            run_job(_static_car(True), progress=False)
