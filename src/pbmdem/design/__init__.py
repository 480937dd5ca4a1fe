"""What the fast model is for: the design space of operating parameters and the estimation of PBM
parameters from measured size distributions, both with PBM-ANN (docs/design.md)."""
