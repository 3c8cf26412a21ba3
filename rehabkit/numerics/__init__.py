"""Small dense linear algebra for control loops: ``triangular`` (Cholesky and triangular solves compiled with
numba, for kernels that solve many systems in a loop) and ``spd3`` (one symmetric 3×3 system in scalar
arithmetic, for a control step's damped pseudoinverse). Import the one you use: only ``triangular`` loads numba."""
