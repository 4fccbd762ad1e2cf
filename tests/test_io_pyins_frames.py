"""pyins-style DataFrames <-> insgnss tables (insgnss.io.pyins_frames), checked against pyins's
own transforms on a pyins-simulated trajectory."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.attitude import dcm_enu_rfu_to_ned_frd, euler_to_dcm
from insgnss.earth import geodetic_to_enu
from insgnss.errors import InputFormatError
from insgnss.io import from_pyins, to_pyins

pyins_sim = pytest.importorskip("pyins.sim")
pyins_transform = pytest.importorskip("pyins.transform")


@pytest.fixture(scope="module")
def motion():
    traj, _ = pyins_sim.generate_sine_velocity_motion(
        0.1, 120.0, [50.0, 60.0, 100.0], [10.0, -5.0, 1.0], velocity_change_amplitude=3.0)
    return traj


def test_from_pyins_matches_pyins_frames(motion):
    ours = from_pyins(motion)
    assert list(ours.columns) == ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll",
                                  "pitch", "heading"]
    np.testing.assert_allclose(np.degrees(ours["lat"]), motion["lat"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours["vel_e"], motion["VE"])
    np.testing.assert_allclose(ours["vel_u"], -motion["VD"])
    assert (ours["heading"] >= 0).all() and (ours["heading"] < 2 * np.pi).all()
    # the attitude is the same rotation: C_frd^ned (pyins) = P C_rfu^enu P (insgnss)
    C_pyins = pyins_transform.mat_from_rph(motion[["roll", "pitch", "heading"]].to_numpy())
    C_ours = dcm_enu_rfu_to_ned_frd(euler_to_dcm(ours["roll"].to_numpy(),
                                                 ours["pitch"].to_numpy(),
                                                 ours["heading"].to_numpy()))
    np.testing.assert_allclose(C_ours, C_pyins, atol=1e-12)
    # positions: pyins's NED offsets from the start equal insgnss's ENU ones, swapped
    ned = pyins_transform.lla_to_ned(motion[["lat", "lon", "alt"]].to_numpy())
    e, n, u = geodetic_to_enu(ours["lat"].to_numpy(), ours["lon"].to_numpy(),
                              ours["height"].to_numpy(), ours["lat"].iloc[0],
                              ours["lon"].iloc[0], ours["height"].iloc[0])
    np.testing.assert_allclose(np.column_stack([n, e, -u]), ned, atol=1e-6)
    assert np.abs(ned).max() > 500.0  # a real excursion


def test_round_trips(motion):
    back = to_pyins(from_pyins(motion))
    np.testing.assert_allclose(back.drop(columns="heading").to_numpy(),
                               motion.drop(columns="heading").to_numpy(), atol=1e-9)
    np.testing.assert_allclose(back["heading"], np.mod(motion["heading"], 360.0), atol=1e-9)
    ours = from_pyins(motion)
    again = from_pyins(to_pyins(ours))
    pd.testing.assert_frame_equal(again, ours, rtol=1e-13, atol=1e-12)


def test_standard_deviations(motion):
    sd = pd.DataFrame({c: np.full(len(motion), v) for c, v in zip(
        ["north", "east", "down", "VN", "VE", "VD", "roll", "pitch", "heading"],
        [1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0.5, 0.6, 1.5], strict=True)}, index=motion.index)
    ours = from_pyins(motion, sd)
    assert ours["east_std"].iloc[0] == 2.0 and ours["up_std"].iloc[0] == 3.0
    assert ours["heading_std"].iloc[0] == pytest.approx(np.radians(1.5))
    t, s = to_pyins(ours, sd=True)
    pd.testing.assert_frame_equal(s.set_axis(sd.index, axis=0), sd, check_names=False)
    with pytest.raises(InputFormatError, match="lacks columns"):
        from_pyins(motion.drop(columns="VD"))
    with pytest.raises(InputFormatError):
        to_pyins(from_pyins(motion), sd=True)  # no *_std columns
