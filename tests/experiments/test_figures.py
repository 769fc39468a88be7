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


def test_figures_say_the_trial_they_were_drawn_at_and_read_plainly(tmp_path, monkeypatch):
    # a return map whose GP mean is flat to 1e-8 drew matplotlib's offset label "1e-8+5.569111e-1"
    # above ticks 4..7, which read as returns from 4 to 7; the figures lag a live run without saying so
    from matplotlib.figure import Figure

    from corl.experiments.figures import ReturnMapData
    from corl.problem import Bounds

    drawn = []
    save = Figure.savefig

    def keep(fig, *args, **kwargs):
        fig.canvas.draw()
        drawn.append(([t.get_text() for t in fig.texts],
                      [axis.get_offset_text().get_text() for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)]))
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    rng = np.random.default_rng(0)
    X = rng.uniform(0, 1, size=(12, 2))
    flat = ReturnMapData(X, np.ones(12, dtype=bool), 0.5569111 + 1e-9 * rng.standard_normal(12),
                         Bounds([0.0, 0.0], [1.0, 1.0]), (X[0], 0.5569111), trial=41)
    plot_return_map(flat, tmp_path / "flat.png")
    x = rng.uniform(0, 1, size=(12, 1))  # returns near 25000: "+2.5e4" above ticks -1..1 without plain ticks
    high = ReturnMapData(x, np.ones(12, dtype=bool), 25000.5 + 0.1 * rng.standard_normal(12), Bounds([0.0], [1.0]),
                         (x[0], 25000.5), trial=7)
    plot_return_map(high, tmp_path / "high.png", labels=("theta",))
    learner = make_method("CORL+PIBU", SyntheticTask((-0.3, 1.2)), seed=0)
    learner.run()
    plot_learning_curve(learner, tmp_path / "lc.png")
    plot_return_map(learner, tmp_path / "rm.png", labels=("theta",))
    last = learner.history[-1][0].index
    assert [texts for texts, _ in drawn] == [["drawn at trial 41"], ["drawn at trial 7"], [f"drawn at trial {last}"],
                                             [f"drawn at trial {last}"]]
    assert all(offset == "" for _, offsets in drawn for offset in offsets), drawn
