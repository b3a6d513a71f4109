"""Wavelet-residual fault detection and offline multisignal wavelet analysis.
ROS-free; the node lives in :mod:`wavelet_fdi.node`."""
