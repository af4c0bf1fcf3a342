"""Studies over many episodes: parameter sweeps, trajectory figures, the thesis reproduction report,
comparisons of policies and convergence in the time step."""
