"""The paper's offline study and the detector's evaluation, composed from the cores.

:mod:`~phfdi.study.paperset` simulates the paper's data sets, :mod:`~phfdi.study.evaluation` runs the
detector and its peers over the scenario matrix, :mod:`~phfdi.study.detector_figures` draws the results.
"""
