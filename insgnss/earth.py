"""Earth model: WGS84/GRS80 ellipsoid, normal gravity, radii of curvature, rotation rates and
geodetic / ECEF / local ENU conversions.

Conventions (see docs/conventions.md): latitude ``lat`` and longitude ``lon`` in radians,
ellipsoidal height ``h`` in metres, local-level frame l = ENU (east, north, up).

Every function here is compiled with numba and works on scalars and on numpy arrays (the same
code serves the per-sample kernels and vectorised Python calls).

References
----------
- Noureldin, Karamat, Georgy, *Fundamentals of Inertial Navigation, Satellite-based Positioning
  and their Integration*, Springer 2013, ch. 2 and 5 (radii eqs. 2.4-2.6, LLF rates eq. 5.36).
- Groves, *Principles of GNSS, Inertial and Multisensor Integrated Navigation Systems*, 2nd ed.,
  2013, eqs. 2.105-2.113 (radii, ECEF), 2.134 (Somigliana), 2.139 (height correction).
- Moritz, "Geodetic Reference System 1980", Bull. Geod. 54 (1980) - series coefficients a1..a6
  in the Heiskanen & Moritz (1967) form.
"""

from __future__ import annotations

import numpy as np

from .aot import entry
from .errors import InvalidValueError
from .jit import njit

# --- WGS84 ellipsoid (GRS80 differs only in 1/f in the 9th digit of b) -------------------------
A = 6378137.0  #: semi-major axis [m]
F = 1.0 / 298.257223563  #: flattening
B = A * (1.0 - F)  #: semi-minor axis [m]
E2 = F * (2.0 - F)  #: first eccentricity squared
OMEGA_E = 7.2921151467e-5  #: Earth rotation rate [rad/s]
GM = 3.986004418e14  #: Earth gravitational constant [m^3/s^2]

# Somigliana normal gravity (WGS84)
GAMMA_E = 9.7803253359  #: normal gravity at the equator [m/s^2]
GAMMA_P = 9.8321849378  #: normal gravity at the poles [m/s^2]
K_SOMIGLIANA = (B * GAMMA_P - A * GAMMA_E) / (A * GAMMA_E)
M_RATIO = OMEGA_E**2 * A**2 * B / GM  #: m = omega^2 a^2 b / GM

# GRS80 series (Heiskanen & Moritz; coefficients as in El-Sheimy's notes)
GRS80_A1 = 9.7803267714
GRS80_A2 = 0.0052790414
GRS80_A3 = 0.0000232718
GRS80_A4 = -0.000003087691089
GRS80_A5 = 0.000000004397731
GRS80_A6 = 0.000000000000721

# international gravity formula on the ellipsoid, inverse-square in height
IGF_G0 = 9.780327
IGF_B1 = 0.0053024
IGF_B2 = 0.0000058
# zonal harmonic J2 of WGS84 (-sqrt(5) C20, C20 = -4.84166774985e-4)
J2 = 1.082629821313e-3

#: gravity model identifiers used by the compiled kernels
GRAVITY_SOMIGLIANA = 0
GRAVITY_GRS80_SERIES = 1
GRAVITY_INVERSE_SQUARE = 2
GRAVITY_J2 = 3
#: the normal gravity models, selectable wherever a ``gravity_model`` is taken
GRAVITY_MODELS = {"somigliana": GRAVITY_SOMIGLIANA, "grs80_series": GRAVITY_GRS80_SERIES,
                  "inverse_square": GRAVITY_INVERSE_SQUARE, "j2": GRAVITY_J2}


def gravity_model_id(name: str | int) -> int:
    """Map a gravity model name (a key of :data:`GRAVITY_MODELS`) to its kernel id."""
    if isinstance(name, int | np.integer) and int(name) in GRAVITY_MODELS.values():
        return int(name)
    try:
        return GRAVITY_MODELS[str(name).lower()]
    except KeyError:
        raise ValueError(
            f"unknown gravity model {name!r}; expected one of {sorted(GRAVITY_MODELS)}"
        ) from None


def check_latitude(lat, where: str = "lat", allow_nan: bool = False) -> None:
    """Raise :class:`~insgnss.errors.InvalidValueError` unless every latitude is finite and in
    [-pi/2, pi/2] radians.

    A value outside that range but within +-90 is almost certainly given in degrees; the message
    says so (``NavState.from_euler(45.07, ...)`` would otherwise run at a latitude of 45 rad).
    ``where`` names the argument or column in the message. ``allow_nan`` lets NaN through (a
    state container that may hold the non-finite state of a diverged filter).
    """
    a = np.asarray(lat, dtype=float)
    bad = np.abs(a) > 0.5 * np.pi + 1e-12
    bad |= np.isinf(a) if allow_nan else ~np.isfinite(a)
    if not np.any(bad):
        return
    i = int(np.flatnonzero(bad.ravel())[0])
    v = float(a.ravel()[i])
    row = None if a.ndim == 0 else i + 1
    if np.isfinite(v) and abs(v) <= 90.0:
        msg = (f"latitude {v:g} rad is outside [-pi/2, pi/2]: it looks like degrees "
               f"({v:g} deg = {np.radians(v):.6f} rad); latitudes are in radians here")
    else:
        msg = f"latitude {v:g} rad is not a latitude"
    raise InvalidValueError(msg, column=where, row=row, expected="radians in [-pi/2, pi/2]")


@njit(cache=True, inline="always")
def _somigliana(s2, h):
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2 * s2)
    return g0 * (
        1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h * h / (A * A)
    )


@njit(cache=True, inline="always")
def gravity_gradient_somigliana(s, c, h):
    """``(dg/dlat [m/s^2/rad], dg/dh [1/s^2])`` of :func:`gravity_somigliana` from ``sin(lat)``,
    ``cos(lat)`` (analytic: ``g = g0(s2) H(s2, h)``, ``ds2/dlat = 2 s c``)."""
    s2 = s * s
    w = 1.0 - E2 * s2
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(w)
    c1 = 1.0 + F + M_RATIO - 2.0 * F * s2
    Hh = 1.0 - 2.0 / A * c1 * h + 3.0 * h * h / (A * A)
    dg0 = g0 * (K_SOMIGLIANA / (1.0 + K_SOMIGLIANA * s2) + 0.5 * E2 / w)
    dH = 4.0 * F / A * h
    return 2.0 * s * c * (dg0 * Hh + g0 * dH), g0 * (-2.0 / A * c1 + 6.0 * h / (A * A))


@njit(cache=True)
def gravity_somigliana(lat, h):
    """Normal gravity magnitude [m/s^2]: Somigliana closed form on the ellipsoid with the
    second-order free-air height correction (Groves eqs. 2.134 and 2.139)."""
    return _somigliana(np.sin(lat) ** 2, h)


@njit(cache=True, inline="always")
def _grs80_series(s2, h):
    return (
        GRS80_A1 * (1.0 + GRS80_A2 * s2 + GRS80_A3 * s2 * s2)
        + (GRS80_A4 + GRS80_A5 * s2) * h
        + GRS80_A6 * h * h
    )


@njit(cache=True)
def gravity_grs80_series(lat, h):
    """Normal gravity magnitude [m/s^2] by the GRS80 series (Heiskanen & Moritz 1967):
    ``g = a1 (1 + a2 sin^2 phi + a3 sin^4 phi) + (a4 + a5 sin^2 phi) h + a6 h^2``."""
    return _grs80_series(np.sin(lat) ** 2, h)


@njit(cache=True, inline="always")
def _inverse_square(s2, h):
    w = 1.0 - E2 * s2
    N = A / np.sqrt(w)
    R = N * np.sqrt((1.0 - E2) / w)  # sqrt(M N)
    g0 = IGF_G0 * (1.0 + IGF_B1 * s2 - IGF_B2 * 4.0 * s2 * (1.0 - s2))  # sin^2 2L = 4 s2 c2
    q = R / (R + h)
    return g0 * q * q


@njit(cache=True)
def gravity_inverse_square(lat, h):
    """Normal gravity [m/s^2]: the international gravity formula on the
    ellipsoid, ``g0 = 9.780327 (1 + 0.0053024 sin^2 lat - 0.0000058 sin^2 2 lat)``, decreasing
    with the inverse square of the distance from a centre at the Gaussian mean radius of
    curvature ``R_G = sqrt(M N)`` below the surface: ``g = g0 R_G^2 / (R_G + h)^2``.

    (Course notes print ``R_G = 6367.449 km`` with this formula: that is the rectifying radius,
    not the radius of the point; the physics is the geometric mean radius of the point.)
    Within 2.2e-6 m/s^2 of Somigliana at the surface; its free-air gradient ``2 g / R_G`` is
    0.34 % below the normal one.
    """
    return _inverse_square(np.sin(lat) ** 2, h)


@njit(cache=True, inline="always")
def _j2(sl, cl, h):
    N = A / np.sqrt(1.0 - E2 * sl * sl)
    x = (N + h) * cl
    z = (N * (1.0 - E2) + h) * sl
    r2 = x * x + z * z
    r = np.sqrt(r2)
    k = 1.5 * J2 * A * A / r2
    zr = z * z / r2
    gx = -GM / (r2 * r) * x * (1.0 + k * (1.0 - 5.0 * zr)) + OMEGA_E * OMEGA_E * x
    gz = -GM / (r2 * r) * z * (1.0 + k * (3.0 - 5.0 * zr))
    return -(gx * cl + gz * sl)


@njit(cache=True)
def gravity_j2(lat, h):
    """Normal gravity [m/s^2] of the J2 field (Groves eq. 2.142):
    gravitation ``-GM/r^3 (r + 3/2 J2 a^2/r^2 ((1 - 5 z^2/r^2) x, (1 - 5 z^2/r^2) y,
    (3 - 5 z^2/r^2) z))`` plus the centrifugal ``w_ie^2 (x, y, 0)``, projected on the ellipsoid
    normal (the small deflection from the normal is not used by a mechanization). Within
    1.2e-4 m/s^2 of Somigliana (the neglected J4 and higher terms).
    """
    return _j2(np.sin(lat), np.cos(lat), h)


@njit(cache=True, inline="always")
def normal_gravity_sc(s, c, h, model):
    """Normal gravity [m/s^2] for a kernel model id from ``sin(lat)``, ``cos(lat)`` (the
    kernels have them; no trigonometry here)."""
    if model == GRAVITY_GRS80_SERIES:
        return _grs80_series(s * s, h)
    if model == GRAVITY_INVERSE_SQUARE:
        return _inverse_square(s * s, h)
    if model == GRAVITY_J2:
        return _j2(s, c, h)
    return _somigliana(s * s, h)


@entry
@njit(cache=True)
def normal_gravity_id(lat, h, model):
    """Normal gravity [m/s^2] for a kernel model id (see :data:`GRAVITY_MODELS`)."""
    return normal_gravity_sc(np.sin(lat), np.cos(lat), h, model)


def normal_gravity(lat, h, model: str | int = "somigliana"):
    """Normal gravity magnitude [m/s^2] at geodetic latitude ``lat`` [rad], height ``h`` [m].

    Parameters
    ----------
    lat, h : float or array_like
        Geodetic latitude [rad] and ellipsoidal height [m].
    model : str
        ``"somigliana"`` (default: closed form with the second-order height correction),
        ``"grs80_series"`` (GRS80 series), ``"inverse_square"`` (international formula) or
        ``"j2"`` (the J2 gravitational field with the centrifugal term).
    """
    mid = gravity_model_id(model)
    lat, h = np.asarray(lat, dtype=float), np.asarray(h, dtype=float)
    if lat.ndim == 0 and h.ndim == 0:
        return float(normal_gravity_id(float(lat), float(h), mid))
    lat, h = (np.ascontiguousarray(a) for a in np.broadcast_arrays(lat, h))
    return normal_gravity_id(lat, h, mid)


@entry
@njit(cache=True)
def radii(lat):
    """Meridian radius M and prime-vertical radius N [m] (Noureldin et al. 2013, ch. 2).

    Returns ``(M, N)``.
    """
    s2 = np.sin(lat) ** 2
    w = 1.0 - E2 * s2
    N = A / np.sqrt(w)
    M = N * (1.0 - E2) / w
    return M, N


@entry
@njit(cache=True)
def earth_rate_l(lat):
    """Earth rotation rate expressed in ENU, ``w_ie^l = (0, we cos lat, we sin lat)`` (eq. 22)."""
    return np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)])


@njit(cache=True)
def transport_rate_l(lat, h, vel):
    """Transport rate ``w_el^l`` of the ENU frame over the ellipsoid (Noureldin et al. 2013, ch. 5).

    ``vel`` is the ENU velocity ``(ve, vn, vu)`` [m/s].
    """
    M, N = radii(lat)
    return np.array(
        [-vel[1] / (M + h), vel[0] / (N + h), vel[0] * np.tan(lat) / (N + h)]
    )


_SCALARS = (float, int, np.floating, np.integer)


def _vector_args(*xs) -> tuple[tuple[np.ndarray, ...], tuple | None]:
    """The arguments of a vectorised kernel as 1-D C-contiguous writable float64 arrays of
    their broadcast shape, and that shape (``None`` when every argument is a scalar).

    numba compiles one specialisation per argument type, and the type includes the layout
    and the read-only flag (a pandas column is read-only, a column slice of a table has
    layout 'A', a scalar is a float): called with whatever the caller has, a small kernel was
    compiled three to four times on a cold cache (about 1 s each). One argument type, one
    compile; the values are the same.
    """
    if all(isinstance(x, _SCALARS) for x in xs):  # the common per-epoch call, fast
        return tuple(np.array([x], dtype=np.float64) for x in xs), None
    arrs = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in xs))
    shape = arrs[0].shape
    flat = tuple(np.require(a.reshape(-1), np.float64, ["C", "W"]) for a in arrs)
    return flat, (shape if shape else None)


def _vector_out(out: tuple, shape: tuple | None) -> tuple:
    """The results of a kernel called through :func:`_vector_args`, in the callers' shape
    (floats for scalar arguments)."""
    if shape is None:
        return tuple(float(o[0]) for o in out)
    return tuple(o.reshape(shape) for o in out)


def geodetic_to_ecef(lat, lon, h) -> tuple:
    """Geodetic (lat, lon [rad], h [m]) to ECEF (x, y, z) [m] (Groves eq. 2.112).

    Scalars or arrays (broadcast); floats for scalar arguments, else arrays of the broadcast
    shape.
    """
    args, shape = _vector_args(lat, lon, h)
    return _vector_out(geodetic_to_ecef_nb(*args), shape)


@entry
@njit(cache=True)
def geodetic_to_ecef_nb(lat, lon, h):
    """:func:`geodetic_to_ecef` in compiled code (scalars there; the Python entry point
    calls it on 1-D float64 arrays only)."""
    _, N = radii(lat)
    cl = np.cos(lat)
    x = (N + h) * cl * np.cos(lon)
    y = (N + h) * cl * np.sin(lon)
    z = (N * (1.0 - E2) + h) * np.sin(lat)
    return x, y, z


@entry
@njit(cache=True)
def ecef_to_geodetic(x, y, z):
    """ECEF (x, y, z) [m] to geodetic (lat, lon [rad], h [m]).

    Bowring's initial value refined by Newton-style fixed-point iterations; accurate to
    well below 1e-9 m for terrestrial and near-Earth points.
    """
    p = np.sqrt(x * x + y * y)
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, p * (1.0 - E2))
    h = p * 0.0
    for _ in range(6):
        s = np.sin(lat)
        N = A / np.sqrt(1.0 - E2 * s * s)
        h = p / np.cos(lat) - N
        lat = np.arctan2(z, p * (1.0 - E2 * N / (N + h)))
    s = np.sin(lat)
    N = A / np.sqrt(1.0 - E2 * s * s)
    # height from the better-conditioned formula near the poles
    h = p * np.cos(lat) + z * s - A * np.sqrt(1.0 - E2 * s * s)
    return lat, lon, h


@entry
@njit(cache=True)
def _ecef_to_enu_matrix(lat, lon):
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    return np.array(
        [[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]]
    )


def ecef_to_enu_matrix(lat: float, lon: float) -> np.ndarray:
    """Rotation matrix ``C_e^l`` from ECEF to the ENU frame at (lat, lon) [rad]."""
    return _ecef_to_enu_matrix(float(lat), float(lon))


def enu_to_ecef_dcm(lat, lon) -> np.ndarray:
    """``C_l^e`` (columns: east, north, up in ECEF; the transpose of :func:`ecef_to_enu_matrix`)
    stacked over ``lat, lon`` [rad] of any shape -> shape + (3, 3)."""
    lat, lon = np.asarray(lat, float), np.asarray(lon, float)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    C = np.empty(np.broadcast(lat, lon).shape + (3, 3))
    C[..., 0, 0], C[..., 1, 0], C[..., 2, 0] = -so, co, 0.0
    C[..., 0, 1], C[..., 1, 1], C[..., 2, 1] = -sl * co, -sl * so, cl
    C[..., 0, 2], C[..., 1, 2], C[..., 2, 2] = cl * co, cl * so, sl
    return C


def ecef_to_enu_vectors(d, lat, lon) -> np.ndarray:
    """Rotate ECEF vectors (N, 3) into the ENU axes at (lat, lon) [rad] (``C_e^l d``, one point
    per row; vectorised :func:`ecef_to_enu_matrix`)."""
    d = np.asarray(d, float)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.column_stack([-so * x + co * y,
                            -sl * co * x - sl * so * y + cl * z,
                            cl * co * x + cl * so * y + sl * z])


def enu_to_ecef_vectors(d, lat, lon) -> np.ndarray:
    """Rotate ENU vectors (N, 3) at (lat, lon) [rad] into ECEF axes (``C_l^e d``)."""
    d = np.asarray(d, float)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    e, n, u = d[:, 0], d[:, 1], d[:, 2]
    return np.column_stack([-so * e - sl * co * n + cl * co * u,
                            co * e - sl * so * n + cl * so * u,
                            cl * n + sl * u])


def geodetic_to_enu(lat, lon, h, lat0: float, lon0: float, h0: float):
    """Geodetic coordinates to local ENU coordinates [m] about the origin (lat0, lon0, h0).

    Vectorised over ``lat, lon, h``. Returns ``(e, n, u)``.
    """
    x, y, z = geodetic_to_ecef(np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float))
    x0, y0, z0 = geodetic_to_ecef(float(lat0), float(lon0), float(h0))
    d = np.stack([np.asarray(x) - x0, np.asarray(y) - y0, np.asarray(z) - z0], axis=-1)
    enu = d @ ecef_to_enu_matrix(lat0, lon0).T
    return enu[..., 0], enu[..., 1], enu[..., 2]


def enu_to_geodetic(e, n, u, lat0: float, lon0: float, h0: float):
    """Local ENU coordinates [m] about (lat0, lon0, h0) to geodetic (lat, lon [rad], h [m])."""
    enu = np.stack([np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)], axis=-1)
    d = enu @ ecef_to_enu_matrix(lat0, lon0)
    x0, y0, z0 = geodetic_to_ecef(float(lat0), float(lon0), float(h0))
    return ecef_to_geodetic(d[..., 0] + x0, d[..., 1] + y0, d[..., 2] + z0)


def enu_displacement_to_geodetic(lat, h, de, dn, du) -> tuple:
    """Small ENU displacement [m] to (dlat, dlon [rad], dh [m]) using the local radii.

    This is the linearised relation used for error-state feedback: ``dlat = dn / (M + h)``,
    ``dlon = de / ((N + h) cos lat)``, ``dh = du``. Scalars or arrays (broadcast); floats
    for scalar arguments, else arrays of the broadcast shape.
    """
    args, shape = _vector_args(lat, h, de, dn, du)
    return _vector_out(_enu_displacement_to_geodetic(*args), shape)


@entry
@njit(cache=True)
def _enu_displacement_to_geodetic(lat, h, de, dn, du):
    """:func:`enu_displacement_to_geodetic` on 1-D float64 arrays (one specialisation)."""
    M, N = radii(lat)
    return dn / (M + h), de / ((N + h) * np.cos(lat)), du


def schuler_period(lat: float = np.pi / 4, h: float = 0.0) -> float:
    """Schuler period ``2 pi sqrt(R / g)`` [s] with the Gaussian mean radius ``sqrt(M N)``."""
    M, N = radii(float(lat))
    return float(2.0 * np.pi * np.sqrt((np.sqrt(M * N) + h) / normal_gravity(lat, h)))


# --- standard atmosphere (barometric height) ------------------------------------------------
#: ICAO standard atmosphere, troposphere: sea-level temperature [K], lapse rate [K/m],
#: sea-level pressure [Pa], exponent R L / (g0 M)
ISA_T0, ISA_LAPSE, ISA_P0, ISA_EXPONENT = 288.15, 0.0065, 101325.0, 0.190263
#: plausible static pressures [Pa] (below sea level to about 11 km)
PRESSURE_RANGE = (2.0e4, 1.1e5)


def pressure_altitude(p) -> np.ndarray:
    """ISA pressure altitude [m] of static pressure ``p`` [Pa]:
    ``h = T0 / L (1 - (p / p0) ** 0.190263)`` (ICAO Doc 7488)."""
    p = np.asarray(p, float)
    return ISA_T0 / ISA_LAPSE * (1.0 - (p / ISA_P0) ** ISA_EXPONENT)
