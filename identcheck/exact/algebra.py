"""Small 3-D algebra over any field — Python ``Fraction``, FLINT ``fmpq`` or ``nmod`` (integers modulo p) —
for the exact certificates: vectors and matrices as lists, rational rotations, random primes.

Only field operations are used, so the same formula gives an exact rational answer or its image modulo
a prime (:mod:`identcheck.certify.tree_rank`, :mod:`identcheck.certify.twin`).
"""
from __future__ import annotations

import random

import flint


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def mv(R, v):
    return [dot(R[0], v), dot(R[1], v), dot(R[2], v)]


def mm(A, B):
    return [[A[i][0] * B[0][j] + A[i][1] * B[1][j] + A[i][2] * B[2][j] for j in range(3)] for i in range(3)]


def transpose(A):
    return [[A[j][i] for j in range(3)] for i in range(3)]


def add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def scale(s, a):
    return [s * a[0], s * a[1], s * a[2]]


def axis_rotation(a, c, s):
    """Rot(a, θ) = c I + s [a]× + (1 − c) a aᵀ for a unit vector a, with (c, s) = (cos θ, sin θ)."""
    one = 1 - c
    return [[c + one * a[0] * a[0], one * a[0] * a[1] - s * a[2], one * a[0] * a[2] + s * a[1]],
            [one * a[1] * a[0] + s * a[2], c + one * a[1] * a[1], one * a[1] * a[2] - s * a[0]],
            [one * a[2] * a[0] - s * a[1], one * a[2] * a[1] + s * a[0], c + one * a[2] * a[2]]]


def quaternion_rotation(w, x, y, z):
    """The rotation of quaternion (w, x, y, z) ≠ 0: entries are quadratic forms over |q|², so rational
    quaternions give rational rotations."""
    inv = 1 / (w * w + x * x + y * y + z * z)
    return [[(w * w + x * x - y * y - z * z) * inv, 2 * (x * y - w * z) * inv, 2 * (x * z + w * y) * inv],
            [2 * (x * y + w * z) * inv, (w * w - x * x + y * y - z * z) * inv, 2 * (y * z - w * x) * inv],
            [2 * (x * z - w * y) * inv, 2 * (y * z + w * x) * inv, (w * w - x * x - y * y + z * z) * inv]]


def half_angle(t):
    """(cos θ, sin θ) of the angle whose half-tangent is t: ((1 − t²), 2t) / (1 + t²), exact."""
    d = 1 + t * t
    return (1 - t * t) / d, 2 * t / d


def random_prime(rng: random.Random, bits: int) -> int:
    """A prime uniform among the odd primes of [2^(bits-1), 2^bits): uniform odd integers, kept when
    prime (FLINT's fmpz_is_prime proves primality)."""
    while True:
        n = rng.getrandbits(bits) | (1 << (bits - 1)) | 1
        if flint.fmpz(n).is_prime():
            return n
