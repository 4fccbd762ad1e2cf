"""Heading re-initialisation of a land vehicle from the GNSS course over ground.

Why
---
The error-state filter linearises the attitude error (``C_nom = (I + [phi x]) C_true``): with a
heading error of 90 or 180 degrees (a wrong given heading, a course taken while reversing, an
IMU mounted the other way round) the linear model is meaningless, the GNSS innovations run away
and the health check stops the run. A land vehicle moves along its forward axis (no side slip:
the same physics as the non-holonomic constraint), so while it drives the GNSS course over
ground *is* its heading to within the side slip; a heading that disagrees with it by tens of
degrees for seconds, while the GNSS innovations are large, is wrong, and the course gives a
better one.

Trigger (:class:`HeadingMonitor`)
---------------------------------
At every epoch before the update (the error state is then zero), for each GNSS course sample up
to the epoch with horizontal speed ``>= min_speed``: the difference ``d = wrap(course - psi)``
between the course and the nominal heading ``psi = atan2(C[0, 1], C[1, 1])`` of the body
forward axis (``y``, right-forward-up). A sample with ``|d| > angle`` extends the current run of
disagreeing samples (a new run starts when the previous disagreeing sample is more than
``duration`` old); one with ``|d| <= angle`` ends it; slower samples neither extend nor end it.
The heading is re-initialised when a run has lasted ``duration`` seconds over at least 3
samples *and* the median over the run's earlier epochs of the largest ``NIS / dof`` of the
absolute measurements (GNSS) at each epoch exceeds ``min_nis`` (a car that reverses with a correct
heading has a course 180 degrees off its forward axis, but consistent innovations: no reset).

Re-initialisation (:func:`reset_covariance`)
---------------------------------------------
The nominal heading is rotated to the course (an attitude feedback ``phi = (0, 0, d)``,
``C <- exp(-[phi x]) C``: a rotation about the local vertical that keeps roll and pitch) and the
horizontal nominal velocity is set to the GNSS velocity of the sample (the INS velocity was
integrated along the wrong direction). The error covariance is reset consistently: the rows and
columns of the up misalignment and the east and north velocity errors are zeroed (the new values
do not depend on the old estimates) and their variances set to

- heading: ``sigma_psi^2 = (sigma_v / v)^2 + sigma_slip^2`` (the course error of a velocity with
  per-axis sigma ``sigma_v`` at speed ``v``, and the side slip / yaw mounting),
- velocity: ``sigma_v^2``.

The runaway-NIS windows restart (their values describe the abandoned state). The smoother
treats the re-initialisation as a boundary (the transition stored into that node is zero): the
states before it are smoothed with the measurements before it only, since the linear error
model does not hold across a large heading change.

References: Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems*, 2nd ed., sec. 14.2.3 (heading from the GNSS velocity) and 16.2.1 (initialisation of
an INS/GNSS filter from GNSS).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["CourseTrack", "HeadingReinit", "HeadingMonitor", "reset_covariance",
           "forward_heading"]


@dataclass
class CourseTrack:
    """GNSS course samples: time [s], course over ground [rad, clockwise from north], its
    sigma [rad] (from the velocity sigma and the side slip), the horizontal GNSS velocity
    ``vel_e, vel_n`` [m/s] and its per-axis sigma ``vel_std`` [m/s]."""

    t: np.ndarray
    course: np.ndarray
    course_std: np.ndarray
    vel_e: np.ndarray
    vel_n: np.ndarray
    vel_std: np.ndarray

    @classmethod
    def from_velocity(cls, t, vel_e, vel_n, vel_std, course, slip_std: float) -> CourseTrack:
        """Samples where ``course`` (e.g. :func:`insgnss.align.heading_from_velocity`) is
        finite; ``sigma_psi = hypot(vel_std / speed, slip_std)`` (module docstring)."""
        t, ve, vn = (np.asarray(a, float) for a in (t, vel_e, vel_n))
        sv = np.broadcast_to(np.asarray(vel_std, float), t.shape)
        c = np.asarray(course, float)
        ok = np.isfinite(c) & np.isfinite(ve) & np.isfinite(vn) & np.isfinite(sv) & (sv > 0)
        speed = np.hypot(ve, vn)
        std = np.hypot(sv / np.where(speed > 0, speed, np.inf), slip_std)
        return cls(t[ok], c[ok], std[ok], ve[ok], vn[ok], sv[ok].copy())

    @property
    def speed(self) -> np.ndarray:
        return np.hypot(self.vel_e, self.vel_n)


@dataclass
class HeadingReinit:
    """Settings of the heading re-initialisation (module docstring): the GNSS ``course``,
    the disagreement ``angle`` [rad], the ``duration`` of the disagreement [s], the smallest
    ``min_speed`` [m/s] at which the course counts and the median ``min_nis`` (``NIS / dof``)
    of the absolute measurements over it."""

    course: CourseTrack
    angle: float = np.radians(30.0)
    duration: float = 3.0
    min_speed: float = 5.0
    min_nis: float = 4.0


def forward_heading(C) -> float:
    """Heading [rad] of the body forward axis (``y``, right-forward-up) in ENU: ``atan2(C[0, 1],
    C[1, 1])``."""
    return float(np.arctan2(C[0, 1], C[1, 1]))


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2.0 * np.pi) - np.pi)


@dataclass
class ReinitEvent:
    """A re-initialisation: the course sample index ``k``, the heading change ``d`` [rad] and
    the record for the summary."""

    k: int
    d: float
    record: dict = field(default_factory=dict)


class HeadingMonitor:
    """The trigger of the module docstring over the samples of ``cfg.course``."""

    def __init__(self, cfg: HeadingReinit):
        self.cfg = cfg
        self.i = 0
        self._clear()

    def _clear(self) -> None:
        self.start = None
        self.last = -np.inf
        self.n = 0
        self.nis: list = []
        self.max_d = 0.0

    def note(self, nis: float) -> None:
        """The largest ``NIS / dof`` of the absolute measurements at the epoch just updated
        (NaN: none), counted while a run of disagreeing samples is open."""
        if self.start is not None and np.isfinite(nis):
            self.nis.append(float(nis))

    def due(self, time: float) -> bool:
        """Whether a course sample is due at ``time`` (else :meth:`check` has nothing to do)."""
        c = self.cfg.course
        return self.i < c.t.size and c.t[self.i] <= time + 1e-9

    def check(self, time: float, C) -> ReinitEvent | None:
        """Course samples up to ``time`` against the nominal attitude ``C`` (before the
        update); a :class:`ReinitEvent` when the heading must be re-initialised."""
        c, cfg = self.cfg.course, self.cfg
        psi = forward_heading(C)
        event = None
        while self.i < c.t.size and c.t[self.i] <= time + 1e-9:
            k = self.i
            self.i += 1
            tk = float(c.t[k])
            if np.hypot(c.vel_e[k], c.vel_n[k]) < cfg.min_speed:
                continue
            d = _wrap(float(c.course[k]) - psi)
            if abs(d) <= cfg.angle:
                self._clear()
                continue
            if self.start is None or tk - self.last > cfg.duration:
                self._clear()
                self.start = tk
            self.n += 1
            self.last = tk
            self.max_d = max(self.max_d, abs(d))
            if tk - self.start >= cfg.duration and self.n >= 3 and self.nis \
                    and float(np.median(self.nis)) > cfg.min_nis:
                med = float(np.median(self.nis))
                event = ReinitEvent(k, d, {
                    "time": float(time), "course_time": tk,
                    "old_heading_deg": float(np.degrees(psi) % 360.0),
                    "new_heading_deg": float(np.degrees(c.course[k]) % 360.0),
                    "heading_std_deg": float(np.degrees(c.course_std[k])),
                    "speed": float(np.hypot(c.vel_e[k], c.vel_n[k])),
                    "reason": f"the heading of the forward axis disagreed with the GNSS course "
                              f"by more than {np.degrees(cfg.angle):g} deg (up to "
                              f"{np.degrees(self.max_d):.1f} deg) for "
                              f"{tk - self.start:.1f} s over {self.n} samples faster than "
                              f"{cfg.min_speed:g} m/s, with a median GNSS NIS/dof of "
                              f"{med:.3g} (> {cfg.min_nis:g})"})
                self._clear()
        return event


def reset_covariance(P, att_up: int, vel_en: tuple[int, int], heading_var: float,
                     vel_var: float) -> np.ndarray:
    """``P`` with the rows and columns of the up misalignment ``att_up`` and the horizontal
    velocity errors ``vel_en`` zeroed and their variances set (module docstring)."""
    P = P.copy()
    for i, var in ((att_up, heading_var), (vel_en[0], vel_var), (vel_en[1], vel_var)):
        P[i, :] = 0.0
        P[:, i] = 0.0
        P[i, i] = var
    return P
