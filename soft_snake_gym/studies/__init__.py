"""Studies over the model: parameter sweeps, trajectory figures and the thesis reproduction report."""
