"""The paper's experiments and what a run leaves behind, one module (or package) per product.

* :mod:`~corl.experiments.synthetic`: the synthetic study (Sec. VIII-A, Fig. 1, ``corl bench synthetic``);
* :mod:`~corl.experiments.door`: the door study (Sec. VIII-B, Fig. 3, ``corl bench door``): CORL's
  and DMP+PoWER's runs, the safe region, the curves over trials;
* :mod:`~corl.experiments.sweep`: the ground truth of a task over a theta grid (``corl sweep``);
* :mod:`~corl.experiments.tables`: every text table; :mod:`~corl.experiments.figures`: every figure;
* :mod:`~corl.experiments.run_output`: a run's output folder (``summary.json``, figures, video);
* :mod:`~corl.experiments.html`: one self-contained HTML page per stored run (``corl report``);
* :mod:`~corl.experiments.backends`: where the runs of a study execute (joblib, Ray, Dask).

The methods by name live below the run store, in :mod:`corl.methods` (``corl.experiments.methods``
still imports). Nothing here is needed to learn a skill, and nothing below imports it
(``tools/check_layers.py``); the ``corl`` command line is built on these modules.
"""
