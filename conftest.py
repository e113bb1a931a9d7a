"""Suite-wide setup, loaded by pytest before anything imports numpy.

Bundle adjustment solves many small dense systems; on a 2-core machine that is busy, OpenBLAS's threads
fight for the cores and make it 6-30x slower (measured on the dinosaur reconstruction). One BLAS thread
per process is faster here and gives the same numbers on every run. Notebook kernels started by nbval
inherit the setting. Set OPENBLAS_NUM_THREADS yourself to override it.
"""
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
