"""What one block of :func:`irl._blas.one_blas_thread` costs: the fastest of 5 runs of 200
empty blocks at a size that sets the limit (10^5 states x actions).

    python bench/blas_block_cost.py
"""

from __future__ import annotations

import timeit

from irl._blas import one_blas_thread


def _block() -> None:
    with one_blas_thread(10**5):
        pass


def main() -> None:
    _block()  # threadpoolctl's first look at the loaded libraries is not the block's cost
    per_block = min(timeit.repeat(_block, number=200, repeat=5)) / 200
    print(f"one_blas_thread block: {per_block * 1e6:.1f} microseconds (fastest of 5 x 200)")


if __name__ == "__main__":
    main()
