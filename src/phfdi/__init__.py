"""phfdi: online fault detection for pH control loops.

The application layer shared by the four cores (ph_plant_sim, valve_actuator,
pi_controllers, wavelet_fdi): the block protocol, the run description,
scenario files, the in-process loop and the ``phfdi`` command line.
Importing this package is cheap; submodules load what they need.
"""

__version__ = "0.1.0"
