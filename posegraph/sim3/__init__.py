"""Sim(3): lifting SE3 graphs and monocular scale-drift correction (Strasdat et al. 2010)."""
