"""The shared particle-filter core: the frame chain and its CUDA graphs, particle estimates, resampling, devices and
errors."""
