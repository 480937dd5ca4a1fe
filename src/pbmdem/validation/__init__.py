"""The validation study: PBM-ANN and PBM-constant against the replicated PBM-DEM reference.

Its modules, one concept each: docs/architecture.md ("Packages and modules").
"""
