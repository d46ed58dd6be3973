"""Warp kernels of the S2 multi-camera people tracker: the per-person particle filter, the multi-view HSV colour
descriptor and the volumetric occupancy."""
