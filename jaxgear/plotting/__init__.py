"""Figures (matplotlib). Every function reads a result (or data) and returns a Figure;
nothing here computes an analysis beyond sampling a trajectory to draw it.
"""

from ._orbit import plot_orbit as plot_orbit
