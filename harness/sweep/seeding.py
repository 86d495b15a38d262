"""The generators of many runs at once: run i of a sweep draws from
``np.random.default_rng([seed, i])``, and this seeds NumPy's PCG64 for a whole task without
building a SeedSequence and a bit generator per run.

``default_rng([seed, i])`` is a PCG64 seeded by ``SeedSequence([seed, i])``. Both are
NumPy's documented, stable algorithms (NumPy keeps their streams from version to version):

* SeedSequence (after M. E. O'Neill's ``seed_seq``): the entropy is the 32-bit words of
  each integer, least significant first (0 is one word); they are hashed into a pool of
  four words (``hashmix``, then every word mixed with the hash of every other, ``mix``),
  and ``generate_state`` hashes the pool again into the words asked for, two per 64-bit
  word, the low one first.
* PCG64 takes four 64-bit words: the initial state (the first two, high word first) and
  the stream (the last two); its 128-bit LCG starts at 0 with increment ``2 stream + 1``,
  steps, adds the initial state and steps again.

Here the hashing runs on NumPy arrays of 32-bit words, one element per run, and the two
LCG steps on Python integers; the resulting state is given to one PCG64 per task. The
tests compare the states and the draws with ``default_rng([seed, i])``'s.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pcg64_states"]

# SeedSequence's hash constants
_INIT_A = 0x43B0D7E5
_MULT_A = 0x931E8875
_INIT_B = 0x8B51F9DD
_MULT_B = 0x58F38DED
_MIX_MULT_L = 0xCA01F9DD
_MIX_MULT_R = 0x4973F715
_XSHIFT = 16
_POOL = 4
_MASK32 = 0xFFFFFFFF
# PCG64's 128-bit LCG multiplier
_PCG_MULT = 0x2360ED051FC65DA44385DF649FCCF645
_MASK128 = (1 << 128) - 1


def _words(n):
    """The 32-bit words of a non-negative integer, least significant first (0: one word)."""
    if n < 0:
        raise ValueError(f"a seed must be >= 0, got {n}")
    out = [n & _MASK32]
    n >>= 32
    while n:
        out.append(n & _MASK32)
        n >>= 32
    return out


class _Hash:
    """SeedSequence's running hash constant: the same sequence for every run."""

    def __init__(self, start, mult):
        self.value, self.mult = start, mult

    def __call__(self, words):
        """``hashmix`` of a column of words (uint32 array), advancing the constant."""
        words = words ^ np.uint32(self.value)
        self.value = (self.value * self.mult) & _MASK32
        words = words * np.uint32(self.value)
        return words ^ (words >> np.uint32(_XSHIFT))


def _mix(x, y):
    result = np.uint32(_MIX_MULT_L) * x - np.uint32(_MIX_MULT_R) * y
    return result ^ (result >> np.uint32(_XSHIFT))


def _pools(entropy):
    """SeedSequence's pool for each row of ``entropy`` (runs x words, uint32)."""
    n = entropy.shape[1]
    hashmix = _Hash(_INIT_A, _MULT_A)
    zero = np.zeros(entropy.shape[0], np.uint32)
    pool = [hashmix(entropy[:, j] if j < n else zero) for j in range(_POOL)]
    for src in range(_POOL):
        for dst in range(_POOL):
            if src != dst:
                pool[dst] = _mix(pool[dst], hashmix(pool[src]))
    for src in range(_POOL, n):
        for dst in range(_POOL):
            pool[dst] = _mix(pool[dst], hashmix(entropy[:, src]))
    return pool


def _generate_state(pool, words):
    """``generate_state(words // 2, np.uint64)`` of each pool, as uint64 columns."""
    value = _INIT_B
    out = []
    for j in range(words):
        w = pool[j % _POOL] ^ np.uint32(value)
        value = (value * _MULT_B) & _MASK32
        w = w * np.uint32(value)
        out.append(w ^ (w >> np.uint32(_XSHIFT)))
    return [out[k].astype(np.uint64) | (out[k + 1].astype(np.uint64) << np.uint64(32))
            for k in range(0, words, 2)]


def pcg64_states(seed, indices):
    """The state of ``np.random.default_rng([seed, i]).bit_generator`` for each run i.

    Parameters
    ----------
    seed : int
        The sweep's seed (>= 0).
    indices : sequence of int
        The runs (>= 0).

    Returns
    -------
    list of dict
        One PCG64 ``state`` per run, to be set on a PCG64 (``bit_generator.state = ...``).
    """
    indices = [int(i) for i in indices]
    head = _words(int(seed))
    states = [None] * len(indices)
    groups = {}                                             # runs whose entropy has as many words
    for j, i in enumerate(indices):
        groups.setdefault(1 if 0 <= i <= _MASK32 else len(_words(i)), []).append(j)
    with np.errstate(over="ignore"):
        for size, rows in groups.items():
            if size == 1:
                tail = np.array([indices[j] for j in rows], dtype=np.uint32)[:, None]
            else:
                tail = np.array([_words(indices[j]) for j in rows], dtype=np.uint32)
            entropy = np.hstack((np.tile(np.array(head, dtype=np.uint32), (len(rows), 1)), tail))
            s0, s1, i0, i1 = (c.tolist() for c in _generate_state(_pools(entropy), 8))
            for j, a, b, c, d in zip(rows, s0, s1, i0, i1):
                inc = ((((c << 64) | d) << 1) | 1) & _MASK128
                state = inc                                             # 0 stepped: 0 * mult + inc
                state = (((state + ((a << 64) | b)) & _MASK128) * _PCG_MULT + inc) & _MASK128
                states[j] = {"bit_generator": "PCG64", "state": {"state": state, "inc": inc},
                             "has_uint32": 0, "uinteger": 0}
    return states
