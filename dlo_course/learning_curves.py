"""Learning curves of training runs (the paper's Fig. 4): now drawn in
:mod:`dlo_course.plots` and read by :mod:`dlo_course.rundir`. This module keeps the names
where the lessons import them."""

from dlo_course.plots import plot_learning_curves, run_label  # noqa: F401
from dlo_course.rundir import read_progress  # noqa: F401
