"""Warp kernels of wptrack (installed as ``wptrack.kernels``).

One module per stage; only ``@wp.kernel``, ``@wp.func``, ``@wp.struct`` and ``wp.constant`` live here. No
numpy, cv2 or pyvista: the drivers in :mod:`wptrack` allocate arrays and launch these kernels.
"""
