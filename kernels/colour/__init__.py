"""Warp kernels of the S1 colour particle filter (Barrera et al.): HSI target pixels and 5x5 window counts, the gaussian
walk, the fused predict+score passes and the detection-driven proposal."""
