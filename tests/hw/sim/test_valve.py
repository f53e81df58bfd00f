"""The servo valve: UPP quantisation, PWM periods, overlap, orifice law, catalogue ratings."""

from __future__ import annotations

import math

import pytest

from hw.sim.valve import LPM, Valve, next_period_ns, orifice_flow, quantise_duty


@pytest.mark.parametrize(("duty", "out"), [
    (0.0, 0.0), (25.9, 25.0), (26.0, 26.0), (-17.99, -17.0), (0.99, 0.0), (-0.5, 0.0),
    (100.0, 100.0), (150.0, 100.0), (-1e9, -100.0), (math.nan, 0.0),
])
def test_duty_is_truncated_to_whole_steps_and_clipped(duty: float, out: float) -> None:
    assert quantise_duty(duty, 1.0) == out


def test_coarser_resolution() -> None:
    assert quantise_duty(26.9, 2.5) == 25.0
    assert quantise_duty(-26.9, 2.5) == -25.0


def test_new_duty_waits_for_the_next_325_us_period() -> None:
    period = 325_000
    assert next_period_ns(0, period) == 0
    assert next_period_ns(1, period) == period
    assert next_period_ns(1_000_000, period) == 1_300_000
    assert next_period_ns(1_300_000, period) == 1_300_000


def valve(**kw: float) -> Valve:
    args = {"lap_pos_pct": 25.5, "lap_neg_pct": 16.5, "rated_lpm": 40.0, "rated_drop_pa": 7e6,
            "b_ratio": 2.0, "null_leak_lpm": 0.1, "supply_pa": 7e6, "spool_time_s": 2e-3}
    args.update(kw)
    return Valve.from_ratings(**args)


def test_overlap_per_direction_then_linear_opening() -> None:
    v = valve()
    for spool in (0.0, 10.0, 25.5, -16.5, -5.0):
        assert v.opening(spool) == 0.0
    assert v.opening(26.0) == pytest.approx(0.005)
    assert v.opening(100.0) == pytest.approx(0.745)
    assert v.opening(-17.0) == pytest.approx(-0.005)
    assert v.opening(-100.0) == pytest.approx(-0.835)


def test_rated_flow_at_full_opening_and_3_5_mpa_per_edge() -> None:
    v = valve()
    assert orifice_flow(v.flow_coeff, 3.5e6) == pytest.approx(40.0 * LPM)
    assert orifice_flow(v.flow_coeff_b, 3.5e6) == pytest.approx(80.0 * LPM)


def test_null_leakage_of_a_centred_valve() -> None:
    # P -> A -> T and P -> B -> T, each through two equal edges: a port sits at ps/2
    v = valve()
    ps = 7e6
    assert 2 * v.null_leak * (ps - ps / 2) == pytest.approx(0.1 * LPM)


def test_orifice_law() -> None:
    assert orifice_flow(2e-7, 4e6) == pytest.approx(2e-7 * 2000)
    assert orifice_flow(2e-7, -4e6) == pytest.approx(-2e-7 * 2000)
    assert orifice_flow(0.0, 4e6) == 0.0
    assert orifice_flow(2e-7, 0.0) == 0.0
