"""``make bench``: every benchmark in turn; results land in ``bench/results/``."""

from __future__ import annotations

import sys

import core_bench
import cycles_kl_bench
import reliable_bench


def main() -> int:
    core_bench.main(sys.argv[1:])
    reliable_bench.main(sys.argv[1:])
    cycles_kl_bench.main()
    return 0


if __name__ == "__main__":
    sys.exit(main())
