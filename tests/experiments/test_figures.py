import numpy as np
import pytest

from corl.experiments.figures import plot_learning_curve, plot_return_map
from corl.methods import make_method
from corl.tasks.synthetic import SyntheticTask


def test_figures_are_written_and_not_blank(tmp_path):
    import matplotlib.image as mpimg

    learner = make_method("CORL+PIBU", SyntheticTask((-0.3, 1.2)), seed=0)
    learner.run()
    for path in (plot_learning_curve(learner, tmp_path / "lc.png"),
                 plot_return_map(learner, tmp_path / "rm.png", labels=("theta",))):
        img = mpimg.imread(path)
        assert img.shape[0] > 300 and img.shape[1] > 400
        assert img[..., :3].std() > 0.05  # something was drawn


def test_return_map_needs_a_black_box_step():
    learner = make_method("CORL+PIBU", SyntheticTask((1.0, 0.0)), seed=0)
    with pytest.raises(ValueError, match="black-box step"):
        plot_return_map(learner, "/tmp/never.png")
