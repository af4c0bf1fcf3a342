"""Studies over many episodes.

Parameter sweeps, trajectory figures, the thesis reproduction report, comparisons of policies and
convergence in the time step.
"""
