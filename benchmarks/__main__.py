"""`python -m benchmarks`: run every benchmark, print tables, write benchmarks/results/*.json."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

from benchmarks import ddpg, gymnasium, lockstep, lon, rollout, simulator  # noqa: E402

if __name__ == "__main__":
    lon.main()
    simulator.main()
    rollout.main()
    ddpg.main()
    lockstep.main()
    gymnasium.main()
