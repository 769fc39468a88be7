"""One robot against K: now ``corl bench parallel`` (corl.experiments.parallel); kept as a path to it.

    python benchmarks/parallel_trials.py synthetic --robots 4 --trial-seconds 0.5 --seed 0 --out /tmp/par \
        [--rollout-every-step | --no-rollout-every-step]
"""

from __future__ import annotations

import sys

if __name__ == "__main__":
    from corl.cli import app

    sys.exit(app(["bench", "parallel", *sys.argv[1:]]))
