"""A robot's side of ``corl serve``: ask for a trial, run it, tell how it went (a ROS node can wrap ``main``).

    corl serve --store run.corl --task examples.panda_switch:make_task --rate 500   # the learner
    python -m examples.robot_client http://127.0.0.1:8765                            # beside the robot

``execute`` is the one function to replace: here a simulated Panda stands in for the robot.
"""

import sys

from corl.client import Client
from examples.panda_switch import make_task

panda = make_task()  # the stand-in robot


def execute(t, q):
    """Follow joint positions q (K, Q) at times t (K,) s; return (success, return or None)."""
    outcome = panda.execute(t, q)
    return outcome.success, outcome.return_


def main(url, token=None):
    c = Client(url, token=token)
    while not c.done:
        trial = c.ask()                      # the pending trial again after a crash: nothing runs twice
        success, ret = execute(trial.t, trial.q)
        c.tell(success, ret)
        print(f"trial {trial.index} ({trial.step}): {'success' if success else 'failure'}, return {ret}")
    print(f"done ({c.stop_reason}): best theta {c.best.theta.round(4).tolist()}, return {c.best.return_:.4f}")


if __name__ == "__main__":
    main(*sys.argv[1:])
