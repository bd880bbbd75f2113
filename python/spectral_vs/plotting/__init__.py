"""Figures written to image files: an alignment's convergence (the paper's Fig. 3 and 5),
the model's path onto the scene (Fig. 1), and a servo run (Fig. 6, :func:`plot_servo`).

matplotlib is optional (``pip install spectral_vs[plot]``) and imported only when a figure
is drawn. Figures are made without ``pyplot`` on the Agg canvas, so drawing works without a
display and leaves the caller's matplotlib backend alone.
"""

from spectral_vs.plotting._common import _new_figure  # noqa: F401  (the CLI and benchmarks draw with it)
from spectral_vs.plotting.alignment import render_alignment
from spectral_vs.plotting.convergence import plot_convergence
from spectral_vs.plotting.servo import plot_servo

__all__ = ["plot_convergence", "plot_servo", "render_alignment"]
