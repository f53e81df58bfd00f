"""Gray code: Table 5.1, the section 5.3 rule, every 13-bit word, scalar == vectorised."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hw.gray import (
    binary_to_gray,
    binary_to_gray_array,
    gray_table,
    gray_to_binary,
    gray_to_binary_array,
)

# Table 5.1: decimal, binary, Gray
TABLE_5_1 = [(0, 0b000), (1, 0b001), (2, 0b011), (3, 0b010),
             (4, 0b110), (5, 0b111), (6, 0b101), (7, 0b100)]
WORDS_13 = np.arange(1 << 13)


def section_5_3(gray: int, bits: int) -> int:
    """The thesis's rule bit by bit: binary_i = gray_i XOR binary_(i+1), binary_n = 0."""
    binary, above = 0, 0
    for i in reversed(range(bits)):
        above = ((gray >> i) & 1) ^ above
        binary |= above << i
    return binary


@pytest.mark.parametrize(("n", "gray"), TABLE_5_1)
def test_table_5_1(n: int, gray: int) -> None:
    assert binary_to_gray(n) == gray
    assert gray_to_binary(gray) == n


def test_every_13_bit_word_round_trips_and_follows_section_5_3() -> None:
    for n in range(1 << 13):
        g = binary_to_gray(n)
        assert gray_to_binary(g) == n == section_5_3(g, 13)
        assert g < 1 << 13


def test_the_lookup_table_is_the_decoder() -> None:
    table = gray_table(13)
    assert len(table) == 1 << 13
    assert table == [gray_to_binary(g) for g in range(1 << 13)]


def test_one_bit_changes_per_count() -> None:
    grays = binary_to_gray_array(WORDS_13)
    changed = grays[1:] ^ grays[:-1]
    assert np.all(changed & (changed - 1) == 0) and np.all(changed != 0)


@pytest.mark.parametrize("dtype", [np.uint16, np.int32, np.int64, np.uint64])
def test_vectorised_equals_scalar(dtype: type) -> None:
    words = WORDS_13.astype(dtype)
    grays = binary_to_gray_array(words)
    assert grays.dtype == dtype
    assert grays.tolist() == [binary_to_gray(int(n)) for n in WORDS_13]
    back = gray_to_binary_array(grays)
    assert back.dtype == dtype
    assert back.tolist() == WORDS_13.tolist()
    assert gray_to_binary_array(words).tolist() == [gray_to_binary(int(g)) for g in WORDS_13]


def test_vectorised_leaves_its_input_alone() -> None:
    grays = binary_to_gray_array(WORDS_13)
    before = grays.copy()
    gray_to_binary_array(grays)
    assert np.array_equal(grays, before)


@given(st.integers(min_value=0, max_value=(1 << 64) - 1))
def test_round_trip_up_to_64_bits(n: int) -> None:
    assert gray_to_binary(binary_to_gray(n)) == n
    assert binary_to_gray(gray_to_binary(n)) == n
