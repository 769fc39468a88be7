"""The paper's experiments and what a run leaves behind: benchmark sweeps (Fig. 1, Fig. 3), the
methods by name, figures, text tables, HTML reports and the summary of one run.

Nothing here is needed to learn a skill; the ``corl`` command line is built on these modules.
"""
