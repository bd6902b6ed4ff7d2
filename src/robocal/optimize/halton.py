"""The Halton sequence IPSO starts from, the same numbers as ``scipy.stats.qmc.Halton`` gives (its
scrambled form: Owen's random permutations of each base's digits, drawn from the swarm's generator
in the same order), without importing ``scipy.stats``: that import alone (its docstrings parsed)
took a second of every swarm process, six times the paper's whole swarm.  The tests hold it to
scipy's sequence to the last bit.
"""

from __future__ import annotations

import math

import numpy as np


def primes(n: int) -> list[int]:
    """The first n primes: the sequence's bases, one per dimension."""
    out: list[int] = []
    candidate = 2
    while len(out) < n:
        if all(candidate % p for p in out if p * p <= candidate):
            out.append(candidate)
        candidate += 1
    return out


def permutations(base: int, rng: np.random.Generator) -> np.ndarray:
    """The digit permutations of one base (one row a digit, as many as a double resolves),
    shuffled in place one after another as scipy draws them."""
    count = math.ceil(54 / math.log2(base)) - 1
    rows = np.repeat(np.arange(base)[None], count, axis=0)
    for row in rows:
        rng.shuffle(row)
    return rows


def halton(n: int, d: int, rng: np.random.Generator | None = None, start: int = 0) -> np.ndarray:
    """n points (n, d) in [0, 1)^d from index ``start``: scrambled with permutations drawn from a child of
    ``rng`` (spawned from its seed sequence, for every base before any point, as ``qmc.Halton(d,
    seed=rng)`` does: ``rng``'s own stream is not drawn from), plain without one."""
    bases = primes(d)
    child = None if rng is None else rng.spawn(1)[0]  # scipy's engine owns a child of the generator it is given
    perms = None if child is None else [permutations(b, child) for b in bases]
    index = np.arange(start, start + n, dtype=np.int64)
    out = np.zeros((n, d))
    for j, base in enumerate(bases):
        quotient, scale, value = index.copy(), 1.0 / base, np.zeros(n)
        if perms is None:  # the radical inverse: digits from the least significant on
            while np.any(quotient > 0):
                value += (quotient % base) * scale
                scale /= base
                quotient //= base
        else:  # every digit a double resolves, each through its own permutation
            for row in perms[j]:
                value += row[quotient % base] * scale
                quotient //= base
                scale /= base
        out[:, j] = value
    return out
