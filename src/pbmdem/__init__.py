"""pbmdem: multi-scale PBM-DEM model of high-shear wet granulation with a learned kernel."""

__version__ = "0.1.0"
