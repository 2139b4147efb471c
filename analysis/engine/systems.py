"""Classic benchmark systems (katsura-n, cyclic-n, dense random) as sympy-free term lists."""
from __future__ import annotations

from .ring import Poly, Ring


def katsura(n: int, prime: int = 65521) -> list[Poly]:
    """katsura-n: n+1 variables x0..xn, degree 2^n."""
    ring = Ring([f"x{i}" for i in range(n + 1)], prime)
    x = ring.gens()

    def X(i: int) -> Poly:
        i = abs(i)
        return x[i] if i <= n else ring.zero()

    eqs = [sum((x[i] for i in range(1, n + 1)), ring.zero()) * 2 + x[0] - ring.one()]
    for m in range(n):
        acc = ring.zero()
        for i in range(-n, n + 1):
            acc = acc + X(i) * X(m - i)
        eqs.append(acc - x[m])
    return eqs


def cyclic(n: int, prime: int = 65521) -> list[Poly]:
    """cyclic-n: n variables; degree 70 for n=5, 156 for n=6."""
    ring = Ring([f"x{i}" for i in range(n)], prime)
    x = ring.gens()
    eqs = []
    for k in range(1, n):
        acc = ring.zero()
        for i in range(n):
            term = ring.one()
            for j in range(k):
                term = term * x[(i + j) % n]
            acc = acc + term
        eqs.append(acc)
    prod = ring.one()
    for xi in x:
        prod = prod * xi
    eqs.append(prod - ring.one())
    return eqs


def eco(n: int, prime: int = 65521) -> list[Poly]:
    """eco-n (Morgan's economics problem): n variables x1..xn, degree 2^(n-2).

    (x_k + sum_{i=1}^{n-k-1} x_i x_{i+k}) x_n - k for k = 1..n-1, and x_1 + ... + x_{n-1} + 1.
    """
    ring = Ring([f"x{i}" for i in range(1, n + 1)], prime)
    x = [None] + ring.gens()  # x[1] .. x[n]
    eqs = []
    for k in range(1, n):
        acc = x[k]
        for i in range(1, n - k):
            acc = acc + x[i] * x[i + k]
        eqs.append(acc * x[n] - ring.one() * k)
    eqs.append(sum((x[i] for i in range(1, n)), ring.zero()) + ring.one())
    return eqs
