"""Studies over many episodes: sweeps, the report, comparisons of policies, convergence in the time step."""
