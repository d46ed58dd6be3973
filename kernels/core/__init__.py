"""Warp kernels shared by every tracker: the camera struct and projection, counter-based random streams, block
reductions, resampling (fp64 CDF, four schemes, grouped) and the background statistics of the motion masks."""
