"""Earth model: known values and internal consistency."""

import numpy as np
import pytest

from insgnss import earth


def test_normal_gravity_known_values():
    # WGS84 Somigliana: equator/pole by construction; 45 deg from the published k = 0.00193185265241
    assert earth.normal_gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert earth.normal_gravity(np.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert earth.normal_gravity(np.radians(45), 0.0) == pytest.approx(9.806197769, abs=1e-9)


def test_gravity_models_agree_and_height_gradient():
    lat = np.radians(np.linspace(-89, 89, 50))
    for h in (0.0, 1000.0, 10000.0):
        a = earth.normal_gravity(lat, h, "somigliana")
        b = earth.normal_gravity(lat, h, "grs80_series")
        assert np.max(np.abs(a - b)) < 2e-5  # GRS80 vs WGS84 ellipsoid: ~1e-6 m/s^2 level
    # free-air gradient about -3.086e-6 1/s^2
    grad = earth.normal_gravity(0.7, 100.0) - earth.normal_gravity(0.7, 0.0)
    assert grad / 100.0 == pytest.approx(-3.086e-6, rel=0.01)


def test_inverse_square_gravity_seed_004():
    """Seed 004 eqs. 6-7 with the Gaussian mean radius, at Tehran (35.6892 N, 1190 m)."""
    lat, h = np.radians(35.6892), 1190.0
    g0 = 9.780327 * (1 + 0.0053024 * np.sin(lat) ** 2 - 0.0000058 * np.sin(2 * lat) ** 2)
    M, N = earth.radii(lat)
    R = np.sqrt(M * N)
    assert earth.normal_gravity(lat, h, "inverse_square") == pytest.approx(
        g0 * R**2 / (R + h) ** 2, abs=1e-12)
    assert earth.normal_gravity(lat, h, "inverse_square") == pytest.approx(9.794267, abs=1e-6)
    grid = np.radians(np.linspace(-90, 90, 181))
    d = earth.normal_gravity(grid, 0.0, "inverse_square") - earth.normal_gravity(grid, 0.0)
    assert np.abs(d).max() < 2.5e-6
    # its free-air gradient 2 g / R_G is 0.34 % below the normal one
    grad = (earth.normal_gravity(lat, 100.0, "inverse_square")
            - earth.normal_gravity(lat, -100.0, "inverse_square")) / 200.0
    ref = (earth.normal_gravity(lat, 100.0) - earth.normal_gravity(lat, -100.0)) / 200.0
    assert grad / ref - 1 == pytest.approx(-0.0034, abs=0.0002)


def test_j2_gravity_is_the_gradient_of_the_j2_potential():
    """-dW/dh of W = GM/r (1 - J2 (a/r)^2 P2(sin psi)) + w^2 p^2 / 2 along the ellipsoid
    normal equals the J2 model (an independent route to the same field)."""
    def W(lat, h):
        x, _, z = earth.geodetic_to_ecef(lat, 0.0, h)
        r = np.hypot(x, z)
        p2 = 1.5 * (z / r) ** 2 - 0.5
        return earth.GM / r * (1 - earth.J2 * (earth.A / r) ** 2 * p2) + 0.5 * earth.OMEGA_E**2 * x * x

    for lat_deg, h in [(0.0, 0.0), (35.6892, 1190.0), (60.0, 10000.0), (89.0, 0.0)]:
        lat = np.radians(lat_deg)
        g = -(W(lat, h + 50.0) - W(lat, h - 50.0)) / 100.0
        assert earth.normal_gravity(lat, h, "j2") == pytest.approx(g, abs=2e-9)
    # equator: GM/a^2 (1 + 3/2 J2) - w^2 a
    assert earth.normal_gravity(0.0, 0.0, "j2") == pytest.approx(
        earth.GM / earth.A**2 * (1 + 1.5 * earth.J2) - earth.OMEGA_E**2 * earth.A, abs=1e-12)
    grid = np.radians(np.linspace(-90, 90, 181))
    d = earth.normal_gravity(grid, 0.0, "j2") - earth.normal_gravity(grid, 0.0)
    assert 5e-5 < np.abs(d).max() < 1.3e-4  # the J4 and higher terms of the normal field


def test_every_gravity_model_is_selectable_by_name_and_id():
    for name, i in earth.GRAVITY_MODELS.items():
        assert earth.gravity_model_id(name) == i == earth.gravity_model_id(i)
        assert 9.78 < earth.normal_gravity(0.5, 0.0, name) < 9.84
        assert earth.normal_gravity(0.5, 0.0, i) == earth.normal_gravity_id(0.5, 0.0, i)
    with pytest.raises(ValueError, match="unknown gravity model"):
        earth.gravity_model_id("wgs72")


def test_radii_known_values():
    M, N = earth.radii(0.0)
    assert N == pytest.approx(earth.A)
    assert M == pytest.approx(earth.A * (1 - earth.E2))
    M, N = earth.radii(np.pi / 2)
    assert M == pytest.approx(N)
    assert N == pytest.approx(earth.A / np.sqrt(1 - earth.E2))


def test_ecef_roundtrip_and_known_point():
    x, y, z = earth.geodetic_to_ecef(0.0, 0.0, 0.0)
    assert (x, y, z) == pytest.approx((earth.A, 0.0, 0.0))
    rng = np.random.default_rng(1)
    lat = rng.uniform(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6, 1000)
    lon = rng.uniform(-np.pi, np.pi, 1000)
    h = rng.uniform(-500, 20000, 1000)
    lat2, lon2, h2 = earth.ecef_to_geodetic(*earth.geodetic_to_ecef(lat, lon, h))
    assert np.max(np.abs(lat2 - lat)) < 1e-12
    assert np.max(np.abs(np.angle(np.exp(1j * (lon2 - lon))))) < 1e-12
    assert np.max(np.abs(h2 - h)) < 1e-6


def test_enu_roundtrip_and_direction():
    lat0, lon0, h0 = np.radians(45.0), np.radians(7.0), 100.0
    M, N = earth.radii(lat0)
    e, n, u = earth.geodetic_to_enu(lat0 + 1e-5, lon0, h0, lat0, lon0, h0)
    assert n == pytest.approx(1e-5 * (M + h0), rel=1e-4) and abs(e) < 1e-6
    e, n, u = earth.geodetic_to_enu(lat0, lon0 + 1e-5, h0, lat0, lon0, h0)
    assert e == pytest.approx(1e-5 * (N + h0) * np.cos(lat0), rel=1e-4)
    pts = np.array([[100.0, -50.0, 3.0], [1e4, 2e4, -30.0]])
    lat, lon, h = earth.enu_to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2], lat0, lon0, h0)
    back = np.column_stack(earth.geodetic_to_enu(lat, lon, h, lat0, lon0, h0))
    assert np.max(np.abs(back - pts)) < 1e-6


def test_rates():
    lat = np.radians(30.0)
    wie = earth.earth_rate_l(lat)
    assert np.linalg.norm(wie) == pytest.approx(earth.OMEGA_E)
    assert wie[0] == 0.0 and wie[1] > 0 and wie[2] > 0
    M, N = earth.radii(lat)
    w = earth.transport_rate_l(lat, 0.0, np.array([10.0, 20.0, 0.0]))
    assert w == pytest.approx([-20.0 / M, 10.0 / N, 10.0 * np.tan(lat) / N])


def test_schuler_period():
    assert earth.schuler_period(np.radians(45)) / 60 == pytest.approx(84.4, abs=0.2)


def test_vector_rotations_match_the_matrix():
    rng = np.random.default_rng(3)
    lat = rng.uniform(-1.5, 1.5, 20)
    lon = rng.uniform(-3, 3, 20)
    d = rng.normal(size=(20, 3))
    enu = earth.ecef_to_enu_vectors(d, lat, lon)
    for k in range(20):
        assert np.allclose(enu[k], earth.ecef_to_enu_matrix(lat[k], lon[k]) @ d[k])
    assert np.allclose(earth.enu_to_ecef_vectors(enu, lat, lon), d)
