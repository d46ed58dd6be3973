"""Warp kernels of the S3 template tracker (Juza et al.): template rasterization, XOR scoring, the Uncovered Object
Histogram, dynamics, classification, partitioned resampling and occlusion."""
