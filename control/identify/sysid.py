"""System identification of each joint from a ``tracking_actuate`` run (thesis section 6.3).

A valve-controlled hydraulic joint integrates: the valve meters a flow, the
flow is a velocity. So every model here maps controller output u (% duty, as
recorded: positive towards larger readings, before polarity) to **joint
velocity**, and position is its integral. Two model families:

- ``DeadbandModel``, the velocity line of Figure 3.2 (eq. 3.1, 3.2) with a
  deadband, followed by the valve-and-oil-column dynamics::

      w = k₊·(u − d₊)  for u > d₊,   k₋·(u + d₋)  for u < −d₋,   0 between
      v = ωn² / (s² + 2ζωn·s + ωn²) · e^(−s·delay) · w

  Fitted by nonlinear least squares (``scipy.optimize.least_squares``) of
  the simulated velocity against the measured one, with the dead time
  searched over whole samples upwards from 0 until the fit gets worse. The
  second-order part is the hydraulic natural frequency (15–40 Hz on the
  Unimate); with a first-order lag instead, Rotate's lightly damped 15 Hz oil
  column fits a fresh run 76 % in velocity, with this form 92 %.
- ``ArxModel``, ARX(na, nb, nk) by linear least squares on the velocity at a
  coarser ``period_s`` (default 10 ms): ``A(q)·v(t) = B(q)·x(t − nk) + e(t)``,
  with x the block mean of u, or — the default, a Hammerstein model — of the
  deadband line ``w`` above. Plain ARX on raw duty cannot represent the
  deadband and fits poorly; ARX at 1 ms is ill-conditioned (the equation error
  rewards extrapolating a smooth signal) and gives unstable models.

Velocity is not measured: it is the derivative of the encoder position after
a zero-phase low-pass (``cutoff_hz``, default 30 Hz; a Gray-code count of
0.03–0.26 joint units per millisecond would otherwise be 30–260 units/s of
noise, and above ~30 Hz that noise outweighs the joint's own motion). The same
filter is applied to the simulated velocity, so the comparison is like for
like, and ARX is fitted to the filtered position's block velocity;
``cutoff_hz=None`` uses the position as recorded. Coupled encoders are undone
first: the Yaw reading includes Bend (rtshare.h ``joint_dep``), so Yaw is
identified on ``reading − coupling·Bend``, the actuator's own coordinate.

Fit figures are MATLAB's NRMSE fit, ``100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖)`` %, of a
free-run simulation (never a one-step prediction) from the run's first
position at rest, in position and in velocity. Use a fresh run for them
(``validate``): on the run a model was fitted to they flatter it.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import scipy  # its signal and optimize load on first use: 1.2 s no importer need pay
from numpy.typing import ArrayLike

from control.recorder import Run
from hw.machine import Joint, Machine
from hw.transmission import Transmission, output_min_pwm

DEFAULT_CUTOFF_HZ = 30.0  # identification band: above it Gray-code quantisation noise dominates
MAX_DELAY_S = 0.005
ARX_PERIOD_S = 0.01
ARX_ORDERS = (2, 3, 1)
NOMINAL_WN = 2 * math.pi * 20.0  # rad/s, initial guess: the middle of the Unimate's 15–35 Hz
NOMINAL_ZETA = 0.5
MOVING_FRACTION = 0.05  # samples faster than this share of the peak speed count as moving
MIN_MOVING = 50  # samples each way needed to fit a direction's line


@dataclass(frozen=True)
class JointSeries:
    """One joint of a run: ``duty (N,)`` % controller output, ``position (N,)`` in the
    joint's unit at sample time ``dt`` (s), coupled encoders undone."""

    name: str
    unit: str
    dt: float
    duty: np.ndarray
    position: np.ndarray

    @property
    def samples(self) -> int:
        return len(self.duty)


@dataclass(frozen=True)
class Fit:
    """NRMSE fit (%) of a free-run simulation: position, and velocity (filtered or per block)."""

    position_pct: float
    velocity_pct: float


@dataclass(frozen=True)
class DeadbandModel:
    """Velocity line with deadband (Figure 3.2) and second-order velocity dynamics.

    ``k_pos``, ``k_neg`` velocity gain, joint units/s per %; ``d_pos``, ``d_neg``
    ≥ 0 the deadband each way, % of controller output; ``wn`` rad/s and
    ``zeta`` the dynamics (unit gain); ``delay_s`` dead time.
    """

    name: str
    unit: str
    k_pos: float
    d_pos: float
    k_neg: float
    d_neg: float
    wn: float
    zeta: float
    delay_s: float = 0.0

    def steady(self, duty: ArrayLike) -> np.ndarray:
        """Steady-state velocity (units/s) at constant ``duty`` (%), eq. 3.1/3.2's form."""
        u = np.asarray(duty, dtype=float)
        return np.where(u > self.d_pos, self.k_pos * (u - self.d_pos),
                        np.where(u < -self.d_neg, self.k_neg * (u + self.d_neg), 0.0))

    def velocity(self, duty: ArrayLike, dt: float) -> np.ndarray:
        """Simulated velocity ``(N,)`` (units/s, at t = k·dt) for ``duty (N,)`` held per sample,
        starting at rest."""
        w = self.steady(duty)
        lag = round(self.delay_s / dt)
        if lag:
            w = np.concatenate([np.zeros(lag), w[:-lag]])
        num, den = _second_order(self.wn, self.zeta, dt)
        return scipy.signal.lfilter(num, den, w)

    def position(self, duty: ArrayLike, dt: float, start: float) -> np.ndarray:
        """Simulated position ``(N,)`` (units) from ``start``, the velocity integrated."""
        return _integrate(self.velocity(duty, dt), dt, start)


@dataclass(frozen=True)
class ArxModel:
    """``A(q)·v(t) = B(q)·x(t − nk)`` at ``period_s``; ``a (na,)``, ``b (nb,)`` newest first.

    v(t) is the mean velocity over the block ending at t (units/s); x(t) the
    mean over the block starting at t of the deadband line ``static.steady(u)``
    (units/s), or of u itself (%) when ``static`` is None.
    """

    name: str
    unit: str
    a: tuple[float, ...]
    b: tuple[float, ...]
    nk: int
    period_s: float
    static: DeadbandModel | None

    @property
    def orders(self) -> tuple[int, int, int]:
        return len(self.a), len(self.b), self.nk

    def velocity(self, duty: ArrayLike, dt: float) -> np.ndarray:
        """Simulated block velocities ``(K + 1,)`` for ``duty (N,)`` at ``dt``; entry 0 is the
        rest the run starts from, entry t the block ending at t·period_s."""
        x = self._input(np.asarray(duty, dtype=float), dt)
        num = np.concatenate([np.zeros(self.nk), self.b])
        return scipy.signal.lfilter(num, np.concatenate([[1.0], self.a]), np.append(x, 0.0))

    def position(self, duty: ArrayLike, dt: float, start: float) -> np.ndarray:
        """Simulated position at the block boundaries ``(K + 1,)`` from ``start``."""
        v = self.velocity(duty, dt)
        return start + self.period_s * np.concatenate([[0.0], np.cumsum(v[1:])])

    def _input(self, duty: np.ndarray, dt: float) -> np.ndarray:
        return _block_input(duty, dt, self.period_s, self.static)


@dataclass(frozen=True)
class Identification:
    """Both models of one joint and their fit on the run they were fitted to."""

    joint: int
    deadband: DeadbandModel
    arx: ArxModel
    deadband_fit: Fit
    arx_fit: Fit


def joint_series(run: Run, machine: Machine, joint: int | str) -> JointSeries:
    """Joint ``joint`` of ``run`` (a ``tracking_actuate`` run, or any run with duty and
    position); a coupled encoder's reading is turned back into its actuator's coordinate."""
    j = machine.joint_index(joint) if isinstance(joint, str) else int(joint)
    spec = machine.joints[j]
    position = Transmission(machine).actuators_of(run.actual)[:, j]  # rtshare.h joint_dep
    return series(run.duty[:, j], position, run.sample_time_s, spec.name, spec.unit)


def series(duty: ArrayLike, position: ArrayLike, dt: float, name: str = "joint",
           unit: str = "") -> JointSeries:
    """A ``JointSeries`` from arrays, checked: same length, finite, at least 1 s of data."""
    u = np.asarray(duty, dtype=float)
    q = np.asarray(position, dtype=float)
    if u.ndim != 1 or u.shape != q.shape:
        raise ValueError(f"{name}: duty and position must be (N,) of one length, got "
                         f"{u.shape} and {q.shape}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"{name}: sample time must be positive seconds, got {dt}")
    if len(u) * dt < 1.0:
        raise ValueError(f"{name}: {len(u) * dt:.3g} s of data; identification needs at "
                         "least 1 s (a few seconds of PRBS is typical)")
    if not (np.isfinite(u).all() and np.isfinite(q).all()):
        raise ValueError(f"{name}: the run holds NaN duty or position: record it in "
                         "tracking_actuate mode")
    return JointSeries(name=name, unit=unit, dt=float(dt), duty=u, position=q)


def nominal(joint: Joint) -> DeadbandModel:
    """The machine file's prior in controller-output terms: deadband = the valve's minimum
    PWM (section 5.4.1) on the side the polarity maps u to, 100 % duty ≈ ``max_speed``."""
    d_pos, d_neg_valve = output_min_pwm(joint)
    d_neg = d_neg_valve / joint.down_scale  # negative output is scaled down (section 3.6)
    return DeadbandModel(
        name=joint.name, unit=joint.unit,
        k_pos=joint.max_speed / (100.0 - d_pos), d_pos=d_pos,
        k_neg=joint.down_scale * joint.max_speed / (100.0 - d_neg_valve), d_neg=d_neg,
        wn=NOMINAL_WN, zeta=NOMINAL_ZETA,
    )


def identify(run: Run, machine: Machine, joint: int | str, *,
             arx_orders: tuple[int, int, int] = ARX_ORDERS, arx_period_s: float = ARX_PERIOD_S,
             cutoff_hz: float | None = DEFAULT_CUTOFF_HZ) -> Identification:
    """Fit both models of ``joint`` to ``run``, starting from the machine file's prior."""
    j = machine.joint_index(joint) if isinstance(joint, str) else int(joint)
    data = joint_series(run, machine, j)
    deadband = fit_deadband(data, initial=nominal(machine.joints[j]), cutoff_hz=cutoff_hz)
    na, nb, nk = arx_orders
    arx = fit_arx(data, na, nb, nk, period_s=arx_period_s, static=deadband, cutoff_hz=cutoff_hz)
    return Identification(joint=j, deadband=deadband, arx=arx,
                          deadband_fit=validate(deadband, data, cutoff_hz=cutoff_hz),
                          arx_fit=validate(arx, data, cutoff_hz=cutoff_hz))


def identify_all(run: Run, machine: Machine, *,
                 arx_orders: tuple[int, int, int] = ARX_ORDERS, arx_period_s: float = ARX_PERIOD_S,
                 cutoff_hz: float | None = DEFAULT_CUTOFF_HZ) -> tuple[Identification, ...]:
    """``identify`` every joint of ``machine`` from one run that excited them all at once
    (``excitation.combine``)."""
    return tuple(identify(run, machine, j, arx_orders=arx_orders, arx_period_s=arx_period_s,
                          cutoff_hz=cutoff_hz) for j in range(machine.n_joints))


def fit_deadband(data: JointSeries, *, initial: DeadbandModel | None = None,
                 cutoff_hz: float | None = DEFAULT_CUTOFF_HZ,
                 max_delay_s: float = MAX_DELAY_S) -> DeadbandModel:
    """Least-squares ``DeadbandModel`` of ``data``; ``initial`` is the starting guess
    (default: lines through the moving samples)."""
    start = initial or _line_guess(data, cutoff_hz)
    measured = smoothed_velocity(data, cutoff_hz)
    x0 = np.array([start.k_pos, start.d_pos, start.k_neg, start.d_neg, start.wn, start.zeta])
    nyquist = math.pi / data.dt
    lower = [1e-9, 0.0, 1e-9, 0.0, 2 * math.pi, 0.05]
    upper = [np.inf, 99.0, np.inf, 99.0, 0.9 * nyquist, 5.0]
    x0 = np.clip(x0, lower, [1e9, 98.0, 1e9, 98.0, 0.8 * nyquist, 4.0])
    best: tuple[float, DeadbandModel] | None = None
    for lag in range(round(max_delay_s / data.dt) + 1):
        result = scipy.optimize.least_squares(_residual, x0, bounds=(lower, upper), x_scale="jac",
                                        args=(data, lag, cutoff_hz, measured))
        if best is not None and result.cost >= best[0]:
            break  # the cost grows with the dead time from here on
        best = (result.cost, _candidate(result.x, data, lag))
        x0 = result.x
    assert best is not None
    return best[1]


def fit_arx(data: JointSeries, na: int = ARX_ORDERS[0], nb: int = ARX_ORDERS[1],
            nk: int = ARX_ORDERS[2], *, period_s: float = ARX_PERIOD_S,
            static: DeadbandModel | None = None,
            cutoff_hz: float | None = DEFAULT_CUTOFF_HZ) -> ArxModel:
    """ARX(na, nb, nk) of the block velocity of the low-passed position by linear least
    squares (module docstring). nk ≥ 1: a block's input moves the joint from the block's end
    on."""
    if na < 0 or nb < 1 or nk < 1:
        raise ValueError(f"ARX orders need na ≥ 0, nb ≥ 1, nk ≥ 1, got ({na}, {nb}, {nk})")
    x = _block_input(data.duty, data.dt, period_s, static)
    y = block_velocity(data, period_s, cutoff_hz)
    first = max(na + 1, nk + nb - 1)
    rows = np.arange(first, len(y))
    if len(rows) < 4 * (na + nb):
        raise ValueError(f"{data.name}: {len(rows)} blocks of {period_s:g} s for "
                         f"{na + nb} ARX parameters: record a longer run or use a shorter "
                         "period")
    phi = np.column_stack([-y[rows - i] for i in range(1, na + 1)]
                          + [x[rows - nk - i] for i in range(nb)])
    theta, *_ = np.linalg.lstsq(phi, y[rows], rcond=None)
    return ArxModel(data.name, data.unit, tuple(theta[:na]), tuple(theta[na:]), nk, period_s,
                    static)


def validate(model: DeadbandModel | ArxModel, data: JointSeries, *,
             cutoff_hz: float | None = DEFAULT_CUTOFF_HZ) -> Fit:
    """Fit of ``model``'s free-run simulation to ``data`` (use a run it was not fitted to)."""
    q0 = float(data.position[0])
    if isinstance(model, DeadbandModel):
        v = _smooth(model.velocity(data.duty, data.dt), cutoff_hz, data.dt)
        return Fit(fit_percent(data.position, model.position(data.duty, data.dt, q0)),
                   fit_percent(smoothed_velocity(data, cutoff_hz), v))
    q = block_position(data, model.period_s)
    v = model.velocity(data.duty, data.dt)[: len(q)]
    return Fit(fit_percent(q, model.position(data.duty, data.dt, q0)[: len(q)]),
               fit_percent(block_velocity(data, model.period_s, cutoff_hz)[1:], v[1:]))


def fit_percent(measured: ArrayLike, predicted: ArrayLike) -> float:
    """NRMSE fit, ``100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖)`` % (MATLAB's ``compare``); 100 is perfect."""
    y = np.asarray(measured, dtype=float)
    yhat = np.asarray(predicted, dtype=float)
    spread = np.linalg.norm(y - y.mean())
    if spread == 0.0:
        raise ValueError("the measured signal is constant: a fit percentage is undefined")
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / spread))


def smoothed_velocity(data: JointSeries, cutoff_hz: float | None = DEFAULT_CUTOFF_HZ) -> np.ndarray:
    """Velocity ``(N,)`` units/s: zero-phase low-passed position (None: as recorded), central
    differences."""
    return np.gradient(_smooth(data.position, cutoff_hz, data.dt), data.dt)


def block_position(data: JointSeries, period_s: float) -> np.ndarray:
    """Position at the block boundaries ``(K + 1,)``: every ``period_s / dt``-th sample."""
    return _every(data.position, _block(period_s, data.dt))


def block_velocity(data: JointSeries, period_s: float,
                   cutoff_hz: float | None = DEFAULT_CUTOFF_HZ) -> np.ndarray:
    """Mean velocity of each block of the low-passed position ``(K + 1,)`` (units/s); entry 0
    is 0, the rest the run starts from."""
    q = _every(_smooth(data.position, cutoff_hz, data.dt), _block(period_s, data.dt))
    return np.concatenate([[0.0], np.diff(q) / period_s])


def _every(x: np.ndarray, m: int) -> np.ndarray:
    """Every ``m``-th sample of ``x`` from the first, ending on a whole block."""
    return x[: ((len(x) - 1) // m) * m + 1: m]


def steady_points(data: JointSeries, settle_s: float = 0.1,
                  cutoff_hz: float | None = DEFAULT_CUTOFF_HZ) -> tuple[np.ndarray, np.ndarray]:
    """Figure 3.2's points: ``(duty (K,), velocity (K,))`` for every stretch of constant duty
    longer than twice ``settle_s``, velocity averaged after the first ``settle_s``."""
    u = data.duty
    edges = np.flatnonzero(np.diff(u) != 0.0) + 1
    bounds = np.concatenate([[0], edges, [len(u)]])
    v = smoothed_velocity(data, cutoff_hz)
    settle = round(settle_s / data.dt)
    points = [(u[a], v[a + settle:b].mean()) for a, b in itertools.pairwise(bounds)
              if b - a > 2 * settle]
    if not points:
        return np.empty(0), np.empty(0)
    duty, velocity = np.array(points).T
    return duty, velocity


def _candidate(x: np.ndarray, data: JointSeries, lag: int) -> DeadbandModel:
    """A ``DeadbandModel`` of parameters ``x`` (k₊, d₊, k₋, d₋, ωn, ζ) and ``lag`` samples."""
    return DeadbandModel(data.name, data.unit, *map(float, x), delay_s=lag * data.dt)


def _residual(x: np.ndarray, data: JointSeries, lag: int, cutoff_hz: float | None,
              measured: np.ndarray) -> np.ndarray:
    """Filtered simulated minus measured velocity of the candidate ``x`` (units/s)."""
    simulated = _candidate(x, data, lag).velocity(data.duty, data.dt)
    return _smooth(simulated, cutoff_hz, data.dt) - measured


def _block_input(duty: np.ndarray, dt: float, period_s: float,
                 static: DeadbandModel | None) -> np.ndarray:
    """ARX input: the block means of ``static.steady(duty)`` (or of ``duty``), ``(K,)``."""
    m = _block(period_s, dt)
    x = duty if static is None else static.steady(duty)
    k = (len(x) - 1) // m
    return x[:k * m].reshape(k, m).mean(axis=1)


def _line_guess(data: JointSeries, cutoff_hz: float | None) -> DeadbandModel:
    """Starting lines v = k·(u ∓ d) through the samples that move, one per direction."""
    v = smoothed_velocity(data, cutoff_hz)
    moving = np.abs(v) > MOVING_FRACTION * np.abs(v).max()
    lines = []
    for side in (1.0, -1.0):
        pick = moving & (side * data.duty > 0) & (side * v > 0)
        if pick.sum() < MIN_MOVING:
            way = "positive" if side > 0 else "negative"
            raise ValueError(f"{data.name}: the run hardly moves the joint with {way} duty: "
                             "excite both directions above the minimum PWM")
        slope, intercept = np.polyfit(side * data.duty[pick], side * v[pick], 1)
        lines.append((max(slope, 1e-6), float(np.clip(-intercept / max(slope, 1e-6), 0, 90))))
    (k_pos, d_pos), (k_neg, d_neg) = lines
    return DeadbandModel(data.name, data.unit, k_pos, d_pos, k_neg, d_neg, NOMINAL_WN,
                         NOMINAL_ZETA)


def _second_order(wn: float, zeta: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """ZOH discretisation of ωn² / (s² + 2ζωn·s + ωn²) at ``dt``: (num, den) in z⁻¹."""
    num, den, _ = scipy.signal.cont2discrete(([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn]), dt,
                                             "zoh")
    return np.ravel(num), np.ravel(den)


def _integrate(v: np.ndarray, dt: float, start: float) -> np.ndarray:
    """Trapezoidal integral of velocity samples at t = k·dt, from ``start``."""
    steps = 0.5 * (v[1:] + v[:-1]) * dt
    return start + np.concatenate([[0.0], np.cumsum(steps)])


def _smooth(x: np.ndarray, cutoff_hz: float | None, dt: float) -> np.ndarray:
    """``x`` through a zero-phase 2nd-order Butterworth low-pass; unchanged for None."""
    if cutoff_hz is None:
        return x
    if not 0.0 < cutoff_hz < 0.5 / dt:
        raise ValueError(f"cutoff {cutoff_hz:g} Hz must be between 0 and the Nyquist "
                         f"frequency {0.5 / dt:g} Hz")
    return scipy.signal.sosfiltfilt(scipy.signal.butter(2, cutoff_hz, fs=1.0 / dt, output="sos"), x)


def _block(period_s: float, dt: float) -> int:
    m = round(period_s / dt)
    if m < 1 or abs(m * dt - period_s) > 1e-9 * max(1.0, period_s):
        raise ValueError(f"period {period_s:g} s must be a whole number of samples of {dt:g} s")
    return m
