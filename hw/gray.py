"""Gray code both ways (section 5.3, Table 5.1), for one word or a numpy array of words.

The Unimate's absolute encoders give a 13-bit reflected binary (Gray) code:
one bit changes per count, so a misread bit at a transition is off by one
count, not by half the scale. The section 5.3 rule is
``binary[i] = gray[i] XOR binary[i+1]`` with the bit above the MSB taken as 0
(errata #6). Unrolled, ``binary = gray ^ (gray >> 1) ^ (gray >> 2) ^ ...``, which
the xor-shift cascade below computes in six shifts for any word below 2**64,
with no loop over bits: the control loop calls it once per joint every tick.

Words are non-negative integers below 2**64; the functions do not check that,
to stay cheap on the control path.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def binary_to_gray(n: int) -> int:
    """Gray code of the natural binary number ``n`` (Table 5.1: 2 -> 0b011)."""
    return n ^ (n >> 1)


def gray_to_binary(g: int) -> int:
    """Natural binary number whose Gray code is ``g`` (Table 5.1: 0b011 -> 2)."""
    g ^= g >> 1
    g ^= g >> 2
    g ^= g >> 4
    g ^= g >> 8
    g ^= g >> 16
    g ^= g >> 32
    return g


def gray_table(bits: int) -> list[int]:
    """``gray_to_binary`` of every ``bits``-bit word, indexed by the word (a per-tick lookup)."""
    return gray_to_binary_array(np.arange(1 << bits, dtype=np.int64)).tolist()


def binary_to_gray_array(n: NDArray[np.integer]) -> NDArray[np.integer]:
    """Element-wise :func:`binary_to_gray` of an integer array (new array, same dtype)."""
    n = np.asarray(n)
    return n ^ (n >> 1)


def gray_to_binary_array(g: NDArray[np.integer]) -> NDArray[np.integer]:
    """Element-wise :func:`gray_to_binary` of an integer array (new array, same dtype)."""
    b = np.array(g, copy=True)
    shift = 1
    while shift < 8 * b.dtype.itemsize:
        b ^= b >> shift
        shift <<= 1
    return b
