"""Where the arithmetic runs: the array namespace (NumPy or CuPy), thread pinning,
MKL's FFTs when installed, and the sparse per-pillar sums.

Knows nothing of the half space or of contact.
"""
