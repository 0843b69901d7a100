"""`python -m neoslam.loop.kernels`: compile every kernel into numba's cache (make setup runs it)."""

from neoslam.loop.kernels import compile_all

compile_all()
