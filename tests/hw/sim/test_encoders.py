"""Encoders: the rig's incremental count; the Unimate's multiplexed Gray words, glitches."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hw.gray import gray_to_binary
from hw.machine import load_machine
from hw.sim.encoders import GrayEncoderBoard, Lamp, QuadratureEncoder

UNIMATE = load_machine("unimate2000b")
MS = 1_000_000


# -- quadrature (rig) -----------------------------------------------------------------------

def test_quadrature_reads_zero_wherever_it_powers_up() -> None:
    for start in (0.0, 123.4, 600.0, 1200.0):
        assert QuadratureEncoder(0.1, start).count(start) == 0


def test_initialise_zeroes_at_the_bottom() -> None:
    # section 3.4.1 INITIALISED: drive to the bottom, take that count as zero
    encoder = QuadratureEncoder(0.1, 600.0)
    bottom = encoder.count(0.0)
    assert bottom == -6000
    for x in (0.0, 0.1, 200.0, 600.0, 1199.95):
        assert 0.1 * (encoder.count(x) - bottom) == pytest.approx(x, abs=0.05 + 1e-9)


def test_quadrature_direction_follows_the_gradient_sign() -> None:
    encoder = QuadratureEncoder(-0.1, 50.0)
    assert encoder.count(60.0) == -100
    assert -0.1 * encoder.count(60.0) == pytest.approx(10.0)


# -- Gray-code words (Unimate) --------------------------------------------------------------

def quiet_board(**kw: float) -> GrayEncoderBoard:
    return GrayEncoderBoard(UNIMATE, [0.0] * 6, glitch_scale=0.0, **kw)


@given(st.integers(min_value=0, max_value=5), st.floats(min_value=0.0, max_value=1.0))
def test_words_decode_with_the_thesis_calibration(joint: int, where: float) -> None:
    spec = UNIMATE.joints[joint]
    position = spec.lower + where * (spec.upper - spec.lower)
    word = quiet_board().encode(joint, position)
    reading = spec.encoder.gradient * gray_to_binary(word) + spec.encoder.constant
    assert reading == pytest.approx(position, abs=abs(spec.encoder.gradient) / 2 + 1e-9)


def test_words_clip_at_the_ends_of_the_disk() -> None:
    board = quiet_board()
    assert board.encode(0, 2100.0) == 0  # In/Out: binary 0 is 2041 mm
    assert gray_to_binary(board.encode(2, 200.0)) == (1 << 13) - 1


def test_lamp_is_brighter_the_longer_each_encoder_is_lit() -> None:
    lamp = Lamp.from_machine(UNIMATE)
    assert lamp.heat_s == pytest.approx(UNIMATE.encoder_settle_s / 3)
    fast = lamp.light(1e-3 / 6, 1e-3)  # servodesk: six joints in each 1 ms tick
    thesis = lamp.light(1e-3, 6e-3)  # thesis: 1 ms per joint
    settled = lamp.light(6e-3, 36e-3)  # section 6.2: 6 ms per joint
    assert 0.5 < fast < thesis < settled
    assert settled > 0.95


def scan(board: GrayEncoderBoard, seconds: float, speed: float = 40.0) -> list[list[int]]:
    """Move every joint at ``speed`` units/s from mid-range; the words read every ms."""
    mid = [0.5 * (j.lower + j.upper) for j in UNIMATE.joints]
    words = []
    a0 = list(mid)
    for k in range(1, round(seconds * 1000) + 1):
        a1 = [m + speed * math.sin(k * 1e-3) for m in mid]
        board.update((k - 1) * MS, k * MS, a0, a1)
        words.append(list(board.words))
        a0 = a1
    return words


def test_glitches_off() -> None:
    board = quiet_board()
    scan(board, 2.0)
    assert board.wrong_readings == [0] * 6


def test_a_few_wrong_readings_per_joint_in_a_12_s_move_at_1_ms() -> None:
    # section 6.2, Figure 6.1: two or three per joint, not every reading
    wrong = [0] * 6
    for seed in range(4):
        board = GrayEncoderBoard(UNIMATE, [0.0] * 6, seed=seed)
        scan(board, 12.0)
        wrong = [w + b for w, b in zip(wrong, board.wrong_readings, strict=True)]
    per_joint_move = sum(wrong) / (4 * 6)
    assert 1.0 < per_joint_move < 5.0


def test_no_wrong_readings_when_each_encoder_gets_the_settle_time() -> None:
    board = GrayEncoderBoard(UNIMATE, [0.0] * 6, glitch_scale=100.0,
                             scan_period_s=6 * UNIMATE.encoder_settle_s)
    scan(board, 12.0)
    assert board.wrong_readings == [0] * 6


def test_glitch_scale_raises_the_rate() -> None:
    board = GrayEncoderBoard(UNIMATE, [0.0] * 6, glitch_scale=100.0)
    words = scan(board, 1.0)
    assert 50 < sum(board.wrong_readings) < 6 * len(words) / 2


def test_a_dim_lamp_only_loses_lit_bits() -> None:
    board = GrayEncoderBoard(UNIMATE, [0.0] * 6, glitch_scale=200.0)
    quiet = quiet_board()
    mid = [0.5 * (j.lower + j.upper) for j in UNIMATE.joints]
    for k in range(1, 500):
        board.update((k - 1) * MS, k * MS, mid, mid)
        true = [quiet.encode(j, mid[j]) for j in range(6)]
        for word, expected in zip(board.words, true, strict=True):
            assert word & ~expected == 0


def test_same_seed_same_words_other_seed_other_glitches() -> None:
    def run(seed: int) -> tuple[list[list[int]], list[int]]:
        board = GrayEncoderBoard(UNIMATE, [0.0] * 6, seed=seed, glitch_scale=20.0)
        return scan(board, 2.0), board.wrong_readings

    first, wrong = run(7)
    assert sum(wrong) > 0
    assert run(7) == (first, wrong)
    assert run(8)[0] != first


def test_slow_scan_refreshes_each_word_once_a_scan() -> None:
    board = quiet_board(scan_period_s=0.036)
    words = scan(board, 0.2, speed=400.0)
    changes = sum(a[0] != b[0] for a, b in itertools.pairwise(words))
    assert 4 <= changes <= 6
