"""The elastic half space: influence coefficients of a square element, the DC-FFT
convolution (CPU, GPU and mirror-symmetric quadrant), the choice of FFT library,
and the far-field bounds and multipoles of a pillar's load.

Uses the platform; knows nothing of pillars' springs, CG or detachment.
"""
